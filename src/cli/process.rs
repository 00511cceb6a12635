//! The process around the command line: parses arguments, runs the command, maps errors to
//! exit codes.
//!
//! Exit codes: 0 success; 1 finished, but checks failed (e.g. `slice --strict` on a
//! defective mesh); 2 usage or input error; 130 interrupted.

use clap::Parser;
use std::process::ExitCode;

/// Restores the default SIGPIPE action, which Rust's runtime sets to "ignore": then
/// `dmdsl ... --json | head` ends quietly when the reader goes away, as other command-line
/// tools do, instead of panicking on a failed print. Output is only printed after a bundle
/// is complete, so this never leaves anything half-written.
#[cfg(unix)]
fn default_sigpipe() {
    // SAFETY: called once at start-up, before any other thread exists; SIG_DFL is a valid
    // disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

/// The `dmdsl` program: parses the process's arguments, runs the command and returns its
/// exit code (0 success; 1 finished, but checks failed; 2 usage or input error; 130
/// interrupted).
pub fn main() -> ExitCode {
    #[cfg(unix)]
    default_sigpipe();
    let cli = match super::Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    let json = cli.json();
    match super::run(cli) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            // The library's errors are complete one-line messages (their sources are
            // already in the text), so print them without the cause chain.
            let (code, file, exit, message) = match e.downcast_ref::<crate::Error>() {
                Some(d) => (d.code(), d.file(), d.exit_code() as u8, d.to_string()),
                None => ("internal", None, 2, format!("{e:#}")),
            };
            let message = printable(&message);
            eprintln!("dmdsl: error: {message}");
            if json {
                println!("{}", super::error_json(code, file, &message));
            }
            ExitCode::from(exit)
        }
    }
}

/// `message` with control characters (terminal escape sequences, newlines, …) that it may
/// quote from a hostile input file shown as escapes (`\u{1b}`), so an error stays one
/// harmless line on the terminal.
pub(super) fn printable(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    for c in message.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// A command line clap cannot parse: its message (and with `--json` the JSON error object)
/// and exit code 2; `--help` and `--version` print and exit 0.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let json = std::env::args_os()
        .skip(1)
        .take_while(|a| a != "--")
        .any(|a| a == "--json");
    let _ = e.print();
    if json {
        let text = e.to_string();
        let first = text
            .lines()
            .next()
            .unwrap_or("")
            .trim_start_matches("error: ")
            .to_string();
        println!("{}", super::error_json("usage", None, &first));
    }
    ExitCode::from(2)
}

#[cfg(test)]
mod tests {
    #[test]
    fn printable_escapes_control_characters_only() {
        assert_eq!(
            super::printable("a.stl: found '\u{1b}[2J' in 65 × 48.75 mm\n"),
            "a.stl: found '\\u{1b}[2J' in 65 × 48.75 mm\\n"
        );
    }
}
