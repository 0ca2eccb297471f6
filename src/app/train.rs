//! `anisocb train`. TODO: filled by its issue.

use crate::error::{Error, Result};

#[derive(clap::Args, Debug)]
pub struct Args {}

pub fn run(_args: Args) -> Result<()> {
    Err(Error::config("`train` is not implemented yet"))
}
