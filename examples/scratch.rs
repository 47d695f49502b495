use gearwear::analysis::simulate::{observe, RunSpec};
use gearwear::model::{ModelAConfig, Wear};
use rayon::prelude::*;
fn main() {
    let args: Vec<f64> = std::env::args().skip(1).map(|s| s.parse().unwrap()).collect();
    let ea = args[0];
    let m = ModelAConfig::default_rig().assembly(Wear::fixed_axis(ea)).unwrap().resolve().unwrap();
    let omegas: Vec<f64> = (1..=500).map(|i| i as f64 * 0.01).collect();
    let t0 = std::time::Instant::now();
    let res: Vec<(f64, usize, f64)> = omegas.par_iter().map(|&w| {
        let t = std::time::Instant::now();
        let sys = m.system(w).unwrap();
        let spec = RunSpec::paper(w);
        let st = observe(&sys, Some(&m), &spec, |_, _, _| {}).unwrap();
        (w, st.steps + st.rejected, t.elapsed().as_secs_f64())
    }).collect();
    println!("total {:?}", t0.elapsed());
    for r in res.iter().step_by(25) { println!("{:.2} steps {} time {:.4}", r.0, r.1, r.2); }
    let s: f64 = res.iter().map(|r| r.2).sum();
    println!("cpu sum {s:.2}");
}
