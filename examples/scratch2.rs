use gearwear::analysis::simulate::{observe, RunSpec};
use gearwear::model::{ModelAConfig, Wear};
fn main() {
    let m = ModelAConfig::default_rig().assembly(Wear::fixed_axis(0.8)).unwrap().resolve().unwrap();
    let t = std::time::Instant::now();
    let mut tot = 0;
    for &w in &[0.26, 1.01, 3.01] {
        let sys = m.system(w).unwrap();
        let st = observe(&sys, Some(&m), &RunSpec::paper(w), |_, _, _| {}).unwrap();
        tot += st.steps + st.rejected;
        println!("{w} {:?}", st);
    }
    println!("{:?} per step {:.2} us", t.elapsed(), t.elapsed().as_secs_f64() * 1e6 / tot as f64);
}
