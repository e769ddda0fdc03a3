//! The `volgen` command-line tool.

mod cli;

fn main() -> std::process::ExitCode {
    // Training and rendering allocate the same multi-megabyte tensors every iteration: keep them
    // in the heap rather than mapping and faulting them in anew each time (see the function).
    volrender::tune_malloc();
    cli::run()
}
