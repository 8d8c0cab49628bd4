//! `stipple`: render point clouds from the command line.

fn main() -> std::process::ExitCode {
    stipple_cli::run()
}
