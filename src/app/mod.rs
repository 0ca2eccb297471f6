//! The command-line front end (feature `cli`). Each subcommand lives in its own file with its
//! `Args` struct and a `run` function; all numeric work is in the library.

pub mod audit;
pub mod bench;
pub mod bundle;
pub mod cpu_check;
pub mod dataset;
pub mod demo;
pub mod eval;
pub mod setup;
pub mod simulate;
pub mod train;
pub mod ui;
pub mod upscale;

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "anisocb",
    version,
    about = "Super-resolve low-resolution cloth animations into high-resolution ones with wrinkles (AnisoCBConvNet)",
    long_about = "anisocb turns each frame of a low-resolution cloth animation (a grid, a garment or any \
mesh of triangles and quads) into a mesh with twice the vertices per side and believable wrinkles, by super-resolving its geometry image with \
three small convolutional networks (GeometryNet, BoundaryNet, EnhanceNet).\n\n\
Start with `anisocb demo` (simulate, upscale, compare, write pictures) or `anisocb upscale FRAMES... --out DIR`."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Simulate a cloth scenario (XPBD) at low and/or high resolution; write geometry images, OBJ, previews.
    Simulate(simulate::Args),
    /// Build a training set (LR/HR geometry images, boundary and edge maps) from simulated runs.
    Dataset(dataset::Args),
    /// Train GeometryNet / BoundaryNet / EnhanceNet with Adam; checkpoints, resume, loss curve.
    Train(train::Args),
    /// Assemble GeometryNet, BoundaryNet and EnhanceNet from separate weights files into one bundle.
    Bundle(bundle::Args),
    /// Upscale an OBJ sequence or a geometry.npy to twice the resolution with wrinkles.
    Upscale(Box<upscale::Args>),
    /// Simulate a held-out scenario, upscale it with the embedded weights, compare, write pictures.
    Demo(demo::Args),
    /// Evaluate anisocb against baselines on held-out runs (metrics tables, plots, renders).
    Eval(eval::Args),
    /// Dump every layer's activation of a network as .npy, to compare with another framework.
    Audit(audit::Args),
    /// Measure this machine's FMA peak and the engine's hot paths (GFLOP/s, % of peak).
    Bench(bench::Args),
}

/// Parse `args` and run; returns the process exit code (0 ok, 1 error, 2 usage). Runs on the
/// global worker pool as it is (tests call this from their own threads).
pub fn main_with_args<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    run(args, false)
}

/// [`main_with_args`] for the `anisocb` process's main thread: first builds the global worker
/// pool with this thread in it (`ops::cpu::join_global_pool`, the command's `--threads` or one
/// per core), so ops called from here split their loops without a hand-off to another thread.
pub fn process_main<I, T>(args: I) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    run(args, true)
}

fn run<I, T>(args: I, join_pool: bool) -> i32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let code = if e.use_stderr() { 2 } else { 0 };
            let _ = e.print();
            return code;
        }
    };
    if join_pool {
        let threads = match &cli.command {
            Command::Upscale(a) => a.threads,
            Command::Demo(a) => a.threads,
            Command::Eval(a) => a.threads,
            _ => None,
        };
        // Fails only if a pool already exists; the commands then run on that one.
        let _ = crate::ops::cpu::join_global_pool(threads.unwrap_or(0));
    }
    let r = match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Dataset(a) => dataset::run(a),
        Command::Train(a) => train::run(a),
        Command::Bundle(a) => bundle::run(a),
        Command::Upscale(a) => upscale::run(*a),
        Command::Demo(a) => demo::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Audit(a) => audit::run(a),
        Command::Bench(a) => bench::run(a),
    };
    match r {
        Ok(()) => 0,
        Err(e) => {
            eprintln!("anisocb: error: {}", e.renamed(flag));
            1
        }
    }
}

/// The command-line flag that sets the library's field `field` ([`crate::Error::Invalid`]).
fn flag(field: &'static str) -> &'static str {
    match field {
        "eta" => "--eta",
        "temporal" => "--temporal",
        "batch" => "--batch",
        "patch" => "--patch",
        "canny_sigma" => "--canny-sigma",
        "strain_iters" => "--strain-iters",
        "margin" => "--margin",
        "frames" => "--frames",
        "chunk" => "--chunk",
        "rest" => "--rest",
        "out" => "--out",
        "overwrite" => "--overwrite",
        "device" => "--device",
        "gravity" => "--gravity",
        "fps" => "--fps",
        "material" => "--material",
        "strength" => "--physics-strength",
        "damping" => "--physics-damping",
        "ground" => "--physics-ground",
        "sphere" => "--physics-sphere",
        "cuboid" => "--physics-box",
        "drift_seconds" => "--physics-drift",
        "substeps_per_second" => "--physics-substeps",
        "pins" => "--physics-pin",
        "pin_vertices" => "--physics-pin-vertices",
        "colliders" => "--collider",
        "collider_thickness" => "--collider-thickness",
        "val_frac" => "--val-frac",
        "resume" => "--resume",
        f => f,
    }
}
