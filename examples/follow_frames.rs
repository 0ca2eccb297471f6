//! The physics pass driven by any HR frames of a run pair: the nets' output (`upscale
//! --format npy`), or the truth's own HR frames, which asks how well the pass places the folds
//! when its coarse targets are the truth's (docs/research/wrinkles.md, "The physics pass",
//! "Targets"). Each run's gravity, frame rate, material, held edges and colliders come from its
//! meta.json (`FollowParams::for_run`, as `eval --physics`).
//!
//!   cargo run --release --example follow_frames -- PAIR_DIR FRAMES_DIR OUT_DIR
//!
//! FRAMES_DIR holds `geometry.npy` + `domain.npy` (e.g. PAIR_DIR/hr); OUT_DIR gets the same.

use anisocb::cloth::follow::{FollowParams, Follower};
use anisocb::cloth::run_io::{read_pair, read_run, write_run};
use anisocb::geom::geometry_image::images_to_sequence;
use anisocb::io::json::Value;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let [pair, frames, out] = a.as_slice() else {
        return Err("usage: follow_frames PAIR_DIR FRAMES_DIR OUT_DIR".into());
    };
    let pair = read_pair(Path::new(pair))?;
    let src = read_run(Path::new(frames))?;
    let frames = images_to_sequence(&src.images, &src.domain);
    let lr = (pair.lr.shape[3], pair.lr.shape[2]);
    let cloth = Follower::run(&frames, lr, &FollowParams::for_run(&pair.meta))?;
    write_run(Path::new(out), &cloth, &src.domain, &Value::Null, false)?;
    Ok(())
}
