//! The `volgen` command-line tool.

mod cli;

fn main() -> std::process::ExitCode {
    report_file_size_limits();
    cli::run()
}

/// Past a file-size limit (`ulimit -f`) the kernel kills the writer with SIGXFSZ unless it is
/// ignored; ignored, the write fails with EFBIG and volgen reports which file did not fit,
/// leaving the previous checkpoint in place (files are written to a temporary name first).
fn report_file_size_limits() {
    #[cfg(unix)]
    // SAFETY: setting a signal's disposition to SIG_IGN before any other thread exists.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}
