use noise::allan::{overlapping_avar, AllanCurve, AllanPoint};
use noise::fit::{fit, Term};
use noise::synth::{flicker_approximation, NoiseModel};
use rand::SeedableRng;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let len: usize = args[1].parse().unwrap();
    let trials: usize = args[2].parse().unwrap();
    let n: f64 = args[3].parse().unwrap();
    let b: f64 = args[4].parse().unwrap();
    let k: f64 = args[5].parse().unwrap();
    let tau0 = 0.01;
    let model = NoiseModel { white_density: n, markov: flicker_approximation(b, 0.1, 100.0 * len as f64 * tau0, 4), random_walk: k };
    // truth
    let template = overlapping_avar(&vec![0.0; len].iter().enumerate().map(|(i, _)| i as f64).collect::<Vec<_>>(), &[0..len], tau0);
    let truth_curve = AllanCurve { tau0_s: tau0, segment_lengths: vec![len], points: template.points.iter().map(|p| AllanPoint { avar: model.avar(p.m, tau0), ..*p }).collect() };
    let tf = fit(&truth_curve).unwrap();
    let truth: Vec<f64> = tf.coefficients.iter().map(|p| p.sqrt()).collect();
    println!("truth N {:.4e} B {:.4e} K {:.4e} (gen {n} {b} {k}); truth fit chi2 {:.3e}", truth[0], truth[1], truth[2], tf.chi2);
    for p in &tf.points { print!("{:.2}:{:.3} ", p.tau_s, p.adev / p.model_adev); }
    println!();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut cover = [0usize; 3]; let mut unres = [0usize; 3]; let mut zs: [Vec<f64>; 3] = Default::default();
    let mut pz: [Vec<f64>; 3] = Default::default(); let mut ci_cover = 0usize; let mut ci_total = 0usize; let mut chi = 0.0;
    for _ in 0..trials {
        let v = model.generate(len, tau0, &mut rng);
        let c = overlapping_avar(&v, &[0..len], tau0);
        let f = fit(&c).unwrap();
        chi += f.chi2 / f.dof as f64;
        for j in 0..3 { if f.covariance[j][j] > 0.0 { pz[j].push((f.coefficients[j] - tf.coefficients[j]) / f.covariance[j][j].sqrt()); } }
        for (j, t) in [&f.white, &f.bias_instability, &f.random_walk].iter().enumerate() {
            match t { Term::Resolved { value, sigma } => { let z = (value - truth[j]) / sigma; zs[j].push(z); if z.abs() <= 1.0 { cover[j] += 1; } }, _ => unres[j] += 1 }
        }
        for p in &f.points { let exact = model.avar((p.tau_s / tau0).round() as usize, tau0).sqrt(); ci_total += 1; if exact >= p.adev_low && exact <= p.adev_high { ci_cover += 1; } }
    }
    for j in 0..3 {
        let m = zs[j].iter().sum::<f64>() / zs[j].len() as f64;
        let sd = (zs[j].iter().map(|z| (z - m).powi(2)).sum::<f64>() / zs[j].len() as f64).sqrt();
        println!("term {j}: cover {:.3} unresolved {} z mean {m:.3} sd {sd:.3}", cover[j] as f64 / trials as f64, unres[j]);
    }
    for j in 0..3 { let v = &pz[j]; let m = v.iter().sum::<f64>() / v.len() as f64; let sd = (v.iter().map(|z| (z - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt(); let cov = v.iter().filter(|z| z.abs() <= 1.0).count() as f64 / v.len() as f64; println!("p{j}: z mean {m:.3} sd {sd:.3} cover {cov:.3}"); }
    println!("ADEV CI coverage {:.3}; mean chi2/dof {:.3}", ci_cover as f64 / ci_total as f64, chi / trials as f64);
}
