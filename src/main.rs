fn main() -> std::process::ExitCode {
    gpustar::cli::main_with_args(std::env::args_os())
}
