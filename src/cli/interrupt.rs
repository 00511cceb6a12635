//! Interrupts: SIGINT (Ctrl-C), SIGTERM (what `kill`, `timeout` and service managers send)
//! and SIGHUP (the terminal went away) ask a command to stop; it stops at its next check,
//! removes what it was writing and exits with code 130.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Sets `flag` when the process is asked to stop: SIGINT, SIGTERM or SIGHUP (Ctrl-C or a
/// console close on Windows). A signal that was ignored when dmdsl started stays ignored
/// (`nohup` ignores SIGHUP, a non-interactive shell's background jobs ignore SIGINT), as
/// the caller asked.
pub(crate) fn on_interrupt(flag: Arc<AtomicBool>) {
    #[cfg(unix)]
    let ignored = ignored_signals();
    // Registration fails only if a handler exists already; ignore that.
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed));
    #[cfg(unix)]
    for s in ignored {
        // SAFETY: SIG_IGN is a valid disposition for these signals.
        unsafe {
            libc::signal(s, libc::SIG_IGN);
        }
    }
}

/// The signals of the three that are ignored now.
#[cfg(unix)]
fn ignored_signals() -> Vec<libc::c_int> {
    [libc::SIGINT, libc::SIGTERM, libc::SIGHUP]
        .into_iter()
        .filter(|&s| {
            // SAFETY: `sigaction` is plain old data (all zeros is a valid value); a null new
            // action makes the call only read the current disposition into `old`.
            let mut old: libc::sigaction = unsafe { std::mem::zeroed() };
            let rc = unsafe { libc::sigaction(s, std::ptr::null(), &mut old) };
            rc == 0 && old.sa_sigaction == libc::SIG_IGN
        })
        .collect()
}
