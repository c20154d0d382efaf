use std::time::Instant;
use noise::synth::{NoiseModel, static_samples};
use rand::SeedableRng;
fn main() {
    let n: usize = std::env::args().nth(1).unwrap().parse().unwrap();
    let a = NoiseModel { white_density: 2.5e-3, random_walk: 1e-4, ..Default::default() };
    let g = NoiseModel { white_density: 1.7e-4, random_walk: 1e-5, ..Default::default() };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let s = static_samples(&[a.clone(), a.clone(), a], Some(&[g.clone(), g.clone(), g]), n, 1e-3, 9.8, &mut rng);
    let mut c = s.clone();
    let t = Instant::now();
    let cols = noise::series::Columns::new(&c, 9.8).unwrap();
    println!("columns {:?}", t.elapsed());
    let t = Instant::now();
    let tears = noise::repair::detect_axes(&cols.counts);
    println!("detect {:?} {:?}", t.elapsed(), tears.iter().map(|t| t.fixes.len()).collect::<Vec<_>>());
    for _ in 0..5 {
        let mut c = s.clone();
        let t = Instant::now();
        let _ = noise::analysis::analyze(&mut c, "x", &Default::default()).unwrap();
        println!("analyze {:?}", t.elapsed());
    }
}
