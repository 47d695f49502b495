use clap::Parser;

fn main() -> anyhow::Result<()> {
    gearwear::cli::run(gearwear::cli::Cli::parse())
}
