//! `anisocb audit`: dump every layer's activation as `.npy` to compare with another framework.

use crate::error::{Error, Result};
use crate::io::read_npy;
use crate::nn::audit::audit;
use crate::nn::weights::load_any;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Weights file (one net, or a bundle of three: each gets a subfolder).
    #[arg(long)]
    pub weights: PathBuf,
    /// Input geometry images, (N, 3, H, W) or (3, H, W), float32 .npy.
    #[arg(long)]
    pub input: PathBuf,
    /// Output folder for `<layer>.npy`.
    #[arg(long)]
    pub out: PathBuf,
    /// Compute device: cpu or cuda.
    #[arg(long, default_value = "cpu")]
    pub device: String,
}

pub fn run(a: Args) -> Result<()> {
    let ops = crate::cuda::ops_for_device(&a.device)?;
    let w = load_any(&a.weights)?;
    let mut x = read_npy(&a.input)?;
    if x.rank() == 3 {
        let s = x.shape;
        x = x.reshape(&[1, s[0], s[1], s[2]])?;
    }
    if x.rank() != 4 || x.shape[1] != 3 {
        return Err(Error::format(
            &a.input,
            format!("expected (N, 3, H, W) or (3, H, W), got {:?}", x.shape),
        ));
    }
    if let Some((i, v)) = x.first_non_finite() {
        return Err(Error::format(&a.input, format!("non-finite value {v} at index {i}")));
    }
    let files = audit(ops.as_ref(), &w, &x, &a.out)?;
    println!("wrote {} activations to {}", files.len(), a.out.display());
    Ok(())
}
