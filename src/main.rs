//! `r4d`: the resonance4d command-line tool. Run `r4d --help`.

mod cli;

/// Counts heap bytes for the peak-memory figures in logs.
#[global_allocator]
static ALLOC: resonance4d::alloc::Counting = resonance4d::alloc::Counting;

fn main() -> std::process::ExitCode {
    cli::main()
}
