//! The speed study of `anisocb eval --speed`: does simulating at LR and upscaling beat
//! simulating at HR? Wall-clock time per frame of each, at three grid sizes, for the given
//! (small) model and the paper-size config.

use crate::cloth::scenarios::{run_single, Scenario, ScenarioSpec};
use crate::error::Result;
use crate::geom::geometry_image::sequence_to_images;
use crate::geom::{Domain, GridMesh};
use crate::nn::bundle::AnisoCb;
use crate::nn::config::NetConfig;
use crate::ops::Ops;
use crate::sr::params::UpscaleParams;
use crate::sr::upscale::upscale_images;
use std::time::Instant;

/// The LR grid sides timed (the HR grid is twice each).
pub const SPEED_GRIDS: [usize; 3] = [32, 64, 128];

/// Markdown: time per frame (ms) of LR simulation + upscaling vs HR simulation, for the small
/// (given) and the paper config (random weights: time does not depend on their values), and
/// whether it pays off; 20 simulated frames of the flag per grid, 4 of them upscaled (after a
/// one-frame warm-up), on `ops` and the current worker pool.
pub fn speed_study(ops: &dyn Ops, small: &AnisoCb) -> Result<String> {
    let paper = AnisoCb::new(NetConfig::paper(), 1);
    let mut s = String::from(
        "\n### Speed: (LR simulation + upscaling) vs HR simulation, ms per frame\n\n\
         | LR → HR grid | LR sim | HR sim | upscale small | upscale paper | LR sim + small | LR sim + paper | pays off? |\n\
         |---|---:|---:|---:|---:|---:|---:|---|\n",
    );
    let frames = 20;
    for n in SPEED_GRIDS {
        let time_sim = |w: usize| -> Result<(f64, Vec<GridMesh>)> {
            let mut spec = ScenarioSpec::new(Scenario::Flag);
            spec.w = w;
            spec.h = w;
            spec.frames = frames;
            let t = Instant::now();
            let m = run_single(&spec)?;
            Ok((1e3 * t.elapsed().as_secs_f64() / frames as f64, m))
        };
        let (lr_ms, lr) = time_sim(n)?;
        let (hr_ms, _) = time_sim(2 * n)?;
        let d = Domain::enclosing(&lr, 0.05);
        let img = sequence_to_images(&lr[..4], &d);
        let time_up = |m: &AnisoCb| -> Result<f64> {
            let p = UpscaleParams { batch: 1, ..UpscaleParams::default() };
            upscale_images(ops, m, &img.slice_batch(0, 1), &d, &p, &mut |_| {})?; // warm-up
            let t = Instant::now();
            upscale_images(ops, m, &img, &d, &p, &mut |_| {})?;
            Ok(1e3 * t.elapsed().as_secs_f64() / 4.0)
        };
        let (us, up) = (time_up(small)?, time_up(&paper)?);
        let verdict = match (lr_ms + us < hr_ms, lr_ms + up < hr_ms) {
            (true, true) => "yes, both configs",
            (true, false) => "small config only",
            _ => "no",
        };
        s.push_str(&format!(
            "| {n}² → {}² | {lr_ms:.2} | {hr_ms:.2} | {us:.2} | {up:.2} | {:.2} | {:.2} | {verdict} |\n",
            2 * n,
            lr_ms + us,
            lr_ms + up
        ));
    }
    s.push_str(&format!("\n(device: {}, {} threads)\n", ops.name(), rayon::current_num_threads()));
    Ok(s)
}
