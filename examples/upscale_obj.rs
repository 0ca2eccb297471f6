//! Upscale a folder of OBJ frames from Rust, without the command line: the library alone
//! (`anisocb = { version = "0.1", default-features = false }`: faer, rayon, wide, bytemuck and
//! npyz only). Writes the same bytes as `anisocb upscale IN --out OUT`.
//!
//! ```text
//! cargo run --release --no-default-features --example upscale_obj -- demo-out/lr hr/
//! ```

use anisocb::nn::weights::embedded_model;
use anisocb::pipeline::{upscale_files, Quiet, UpscaleJob};

fn main() -> anisocb::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, out] = args.as_slice() else {
        eprintln!("usage: upscale_obj OBJ_FOLDER OUT_FOLDER");
        std::process::exit(2);
    };
    let model = embedded_model()?;
    let job = UpscaleJob::new(vec![input.into()], out).check()?;
    let done = upscale_files(&anisocb::ops::Cpu, &model, &job, &mut Quiet)?;
    println!("{} frames {:?} -> {:?} in {:.2} s -> {out}", done.frames, done.lr, done.hr, done.seconds);
    Ok(())
}
