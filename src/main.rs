//! Thin entry point: check the CPU, parse arguments, hand over to the library's `app` module.

fn main() {
    // First, before anything that may use the wide instructions this binary was compiled for
    // (see src/app/cpu_check.rs for what this can and cannot guarantee).
    let missing = anisocb::app::cpu_check::missing_cpu_features();
    if !missing.is_empty() {
        let _ = anisocb::app::cpu_check::write_missing_report(&mut std::io::stderr(), missing.as_slice());
        std::process::exit(3);
    }
    // Ctrl-C, or SIGTERM from a farm's scheduler: remove the temporary files of the writes in
    // flight (the outputs already written stay; upscale.json still says "complete": false).
    let _ = ctrlc::set_handler(|| {
        eprintln!(
            "anisocb: interrupted; unfinished temporary files removed (rerun the same command to finish)"
        );
        anisocb::io::atomic::remove_live_temps_and_exit(130)
    });
    std::process::exit(anisocb::app::process_main(std::env::args_os()));
}
