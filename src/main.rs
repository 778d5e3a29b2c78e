//! `r4d`: the resonance4d command-line tool. Run `r4d --help`.

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
