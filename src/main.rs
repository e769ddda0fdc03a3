//! The `volgen` command-line tool.

mod cli;

fn main() -> std::process::ExitCode {
    set_signals();
    cli::run()
}

/// Two signals the Rust runtime leaves as a command-line tool should not have them:
///
/// - Past a file-size limit (`ulimit -f`) the kernel kills the writer with SIGXFSZ unless it is
///   ignored; ignored, the write fails with EFBIG and volgen reports which file did not fit,
///   leaving the previous checkpoint in place (files are written to a temporary name first).
/// - The runtime ignores SIGPIPE, so printing to a pipe whose reader has gone (`volgen info FILE
///   | head -3`) fails, and `println!` panics with a backtrace; with the default disposition
///   the process ends quietly there, as other tools do.
fn set_signals() {
    #[cfg(unix)]
    #[allow(unsafe_code)]
    // SAFETY: setting signals' dispositions before any other thread exists.
    unsafe {
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
