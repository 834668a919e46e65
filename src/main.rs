//! The `gpustar` command line; the library does the work.

mod cli;

fn main() -> std::process::ExitCode {
    cli::main_with_args(std::env::args_os())
}
