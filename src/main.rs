//! The `alphasurf` command line: clap subcommands wired to library calls (see `src/cli/`).

fn main() -> std::process::ExitCode {
    // Rust ignores SIGPIPE, so a closed stdout (`alphasurf devices | head`) turns every later
    // print into a panic; the default disposition ends the process quietly, like other tools.
    #[cfg(unix)]
    // SAFETY: called first thing in main, before any thread exists; only resets a disposition.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    alphasurf::cli::main()
}
