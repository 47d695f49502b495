use gearwear::model::{ModelAConfig, Wear};
use gearwear::solver::{sample_uniform, Dopri5, Dopri5Options, Integrator};
fn main() {
    let cfg = ModelAConfig::default_rig();
    let args: Vec<f64> = std::env::args().skip(1).map(|s| s.parse().unwrap()).collect();
    let (om, ea) = (args[0], args[1]);
    let m = cfg.assembly(Wear::fixed_axis(ea)).unwrap().resolve().unwrap();
    println!("omega_h = {} rad/s ({} Hz)", m.omega_h, m.omega_h / 6.283);
    println!("F = {:?}", m.f);
    println!("c = {:?}", m.c);
    println!("nat = {:?}", m.natural_frequencies());
    println!("A row0 = {:?}", m.a.row(0));
    let sys = m.system(om).unwrap();
    let y0 = vec![0.0; 20];
    let t0 = std::time::Instant::now();
    let mut it = Dopri5::new(&sys, 0.0, &y0, Dopri5Options::default()).unwrap();
    let per = std::f64::consts::TAU / om;
    let trans = 300.0f64.max(100.0 * per);
    let mut pts = vec![];
    let mut mx = f64::MIN; let mut mn = f64::MAX;
    sample_uniform(&mut it, trans, per / 256.0, trans + 80.0 * per, |k, _t, y| {
        if k % 256 == 0 { pts.push((y[0], y[10])); }
        mx = mx.max(y[0]); mn = mn.min(y[0]);
    }).unwrap();
    println!("elapsed {:?} stats {:?}", t0.elapsed(), it.stats());
    println!("x1 range [{mn}, {mx}]");
    for p in pts.iter().take(12) { print!("({:.4},{:.4}) ", p.0, p.1); }
    println!();
}
