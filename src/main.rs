//! The `alphasurf` command line: clap subcommands wired to library calls (see `src/cli/`).

fn main() -> std::process::ExitCode {
    alphasurf::cli::main()
}
