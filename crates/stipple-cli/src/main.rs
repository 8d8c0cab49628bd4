//! `stipple`: render point clouds from the command line.

/// Refused allocations end in a one-line error, not an abort (see `stipple_cli::oom`).
#[global_allocator]
static ALLOCATOR: stipple_cli::oom::Remembering = stipple_cli::oom::Remembering;

fn main() -> std::process::ExitCode {
    stipple_cli::oom::install();
    stipple_cli::run()
}
