//! `shoal`: the command line over the `shoal` library. See `shoal --help`.

fn main() -> std::process::ExitCode {
    shoal::cli::main()
}
