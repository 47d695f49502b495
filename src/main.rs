use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    match gearwear::cli::run(gearwear::cli::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line per cause, most specific last: what failed and why, no backtrace.
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
