//! Cloth simulator cost: ms per frame at 32², 64², 128², 256² vertices with the default
//! substeps (the cost that super-resolution has to beat). Run: `cargo bench --bench sim`.
//! Scenario: flag-sphere (wind, pinned flapping edge, sphere contacts), cotton.

use anisocb::cloth::{Scenario, ScenarioSpec};
use std::time::Instant;

fn main() {
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    println!(
        "cloth XPBD, flag-sphere, {} substeps x 1 iteration per frame",
        ScenarioSpec::new(Scenario::Flag).params.substeps
    );
    println!(
        "{:>10} {:>10} {:>12} {:>14} {:>14} {:>14}",
        "grid", "vertices", "constraints", "ms/frame 1thr", "ms/frame pool", "ns/constraint"
    );
    for n in [32usize, 64, 128, 256] {
        let label = format!("{n}x{n}");
        if filter.as_ref().is_some_and(|f| !label.contains(f.as_str())) {
            continue;
        }
        let mut ms = [0.0f64; 2];
        let mut nc = 0;
        for (k, par_min) in [usize::MAX, 4096].into_iter().enumerate() {
            let mut spec = ScenarioSpec::new(Scenario::FlagSphere);
            spec.w = n;
            spec.h = n;
            spec.params.parallel_min_colour = par_min;
            let (mut cloth, scene) = spec.setup(n, n);
            // Warm up into the swinging regime, then time enough frames for ~0.5 s.
            for _ in 0..5 {
                cloth.step(&spec.params, &scene, None);
            }
            let frames = (2_000_000 / (n * n)).clamp(3, 200);
            let t0 = Instant::now();
            for _ in 0..frames {
                cloth.step(&spec.params, &scene, None);
            }
            ms[k] = t0.elapsed().as_secs_f64() * 1e3 / frames as f64;
            nc = cloth.dist.items.len() + cloth.bend.items.len();
        }
        let per = ms[0] * 1e6 / (nc * ScenarioSpec::new(Scenario::FlagSphere).params.substeps) as f64;
        println!("{label:>10} {:>10} {nc:>12} {:>14.3} {:>14.3} {per:>14.2}", n * n, ms[0], ms[1]);
    }
}
