//! Thin entry point: check the CPU, parse arguments, hand over to the library's `app` module.

fn main() {
    // Before anything that may use the wide instructions this binary was compiled for.
    if let Err(msg) = anisocb::app::cpu::check_cpu_features() {
        eprintln!("anisocb: {msg}");
        std::process::exit(3);
    }
    std::process::exit(anisocb::app::main_with_args(std::env::args_os()));
}
