//! The `jawtrack` command line.

mod cli;

fn main() -> std::process::ExitCode {
    // Output piped into a reader that stops early (`jawtrack ... | head`) ends the program
    // quietly, as other command-line tools do, instead of a panic on the broken pipe.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE at start-up, before any thread
    // exists, is the documented use of signal(2).
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    cli::main()
}
