//! The `ndfit` command-line tool. All work happens in the library; see `src/cli/`.

fn main() -> std::process::ExitCode {
    ndfit_cli::main()
}

#[path = "cli/mod.rs"]
mod ndfit_cli;
