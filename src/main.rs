//! The `dmdsl` command line: parses arguments, calls the library, maps errors to exit codes.
//!
//! Exit codes: 0 success; 1 finished, but checks failed (e.g. `slice --strict` on a
//! defective mesh); 2 usage or input error; 130 interrupted.

mod cli;

use clap::Parser;
use std::process::ExitCode;

/// Restores the default SIGPIPE action, which Rust's runtime sets to "ignore": then
/// `dmdsl ... --json | head` ends quietly when the reader goes away, as other command-line
/// tools do, instead of panicking on a failed print. Output is only printed after a bundle
/// is complete, so this never leaves anything half-written.
#[cfg(unix)]
fn default_sigpipe() {
    unsafe extern "C" {
        fn signal(signum: i32, handler: usize) -> usize;
    }
    const SIGPIPE: i32 = 13;
    const SIG_DFL: usize = 0;
    // SAFETY: called once at start-up, before any other thread exists; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        signal(SIGPIPE, SIG_DFL);
    }
}

fn main() -> ExitCode {
    #[cfg(unix)]
    default_sigpipe();
    let cli = cli::Cli::parse();
    match cli::run(cli) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            match e.downcast_ref::<dmdsl::Error>() {
                // The library's errors are complete one-line messages (their sources are
                // already in the text), so print them without the cause chain.
                Some(d) => {
                    eprintln!("dmdsl: error: {d}");
                    ExitCode::from(d.exit_code() as u8)
                }
                None => {
                    eprintln!("dmdsl: error: {e:#}");
                    ExitCode::from(2)
                }
            }
        }
    }
}
