//! The `dmdsl` binary: the command line of the library (`dmdsl::cli`).

fn main() -> std::process::ExitCode {
    dmdsl::cli::main()
}
