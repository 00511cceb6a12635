//! Typed errors of the library.
//!
//! Every error renders as one line that names the file (or profile, or bundle)
//! and what is wrong with it. The binary maps them to exit codes with
//! [`Error::exit_code`].
//!
//! Nothing panics on bad input; exit code 2 for usage and input errors, 130 for an interrupt
//! (Ctrl-C, SIGTERM, SIGHUP).

use std::path::PathBuf;

/// Result alias used throughout the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in `dmdsl`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system error while reading or writing `path`.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory involved.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// An input file (mesh, CSV table, calibration) is malformed.
    #[error("{}: {msg}", path.display())]
    Input {
        /// The offending file.
        path: PathBuf,
        /// What is wrong, e.g. "line 7: expected 4 columns, found 3".
        msg: String,
    },
    /// A machine profile is invalid (unknown key, missing value, bad number).
    #[error("profile {origin}: {msg}")]
    Profile {
        /// Profile name or file the problem comes from.
        origin: String,
        /// What is wrong.
        msg: String,
    },
    /// The part or the settings cannot produce a job (e.g. part larger than the field).
    #[error("{}: {msg}", path.display())]
    Job {
        /// The part being sliced.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A job bundle cannot be read or is not a dmdsl bundle.
    #[error("{}: {msg}", path.display())]
    Bundle {
        /// The bundle (or a file inside it).
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// An archive (a zipped bundle, an SL1 file, a control-file zip) cannot be read safely:
    /// not a zip, truncated, or an entry that is refused (a path leading outside, a
    /// duplicate name, a size above the bounds, encryption, an unsupported method, a
    /// symbolic link).
    #[error("{}: {}{msg}", path.display(), entry.as_deref().map(|e| format!("entry {e:?}: ")).unwrap_or_default())]
    Archive {
        /// The archive file.
        path: PathBuf,
        /// The entry concerned, when one is.
        entry: Option<String>,
        /// What is wrong.
        msg: String,
    },
    /// Bad command-line usage not caught by the argument parser.
    #[error("{0}")]
    Usage(String),
    /// The command was interrupted (Ctrl-C, SIGTERM or SIGHUP); nothing was written.
    #[error("interrupted; nothing was written")]
    Interrupted,
}

impl Error {
    /// Helper building an [`Error::Io`].
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    /// Helper building an [`Error::Input`].
    pub fn input(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Error::Input {
            path: path.into(),
            msg: msg.into(),
        }
    }

    /// Stable code of this kind of error, for scripts (the `error.code` of `--json`
    /// output): `io.not-found`, `io.permission-denied`, `io.other`, `input.malformed`,
    /// `profile.invalid`, `job.infeasible`, `bundle.invalid`, `archive.invalid`, `usage`,
    /// `interrupted`.
    pub fn code(&self) -> &'static str {
        match self {
            Error::Io { source, .. } => match source.kind() {
                std::io::ErrorKind::NotFound => "io.not-found",
                std::io::ErrorKind::PermissionDenied => "io.permission-denied",
                _ => "io.other",
            },
            Error::Input { .. } => "input.malformed",
            Error::Profile { .. } => "profile.invalid",
            Error::Job { .. } => "job.infeasible",
            Error::Bundle { .. } => "bundle.invalid",
            Error::Archive { .. } => "archive.invalid",
            Error::Usage(_) => "usage",
            Error::Interrupted => "interrupted",
        }
    }

    /// The file (or profile, or bundle) the error is about, if any.
    pub fn file(&self) -> Option<String> {
        match self {
            Error::Io { path, .. }
            | Error::Input { path, .. }
            | Error::Job { path, .. }
            | Error::Bundle { path, .. }
            | Error::Archive { path, .. } => Some(path.display().to_string()),
            Error::Profile { origin, .. } => Some(origin.clone()),
            Error::Usage(_) | Error::Interrupted => None,
        }
    }

    /// Process exit code for this error: 130 for an interrupt, 2 for everything else
    /// (usage and input errors; docs/CLI.md, "Exit codes").
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Interrupted => 130,
            _ => 2,
        }
    }
}

/// The results of a parallel iterator collected in order, or the error of the first item
/// (in the iterator's order) that failed. Rayon's own `collect` into a `Result` returns
/// whichever error a worker met first, so the same input could be refused with one
/// message or another from run to run.
pub(crate) fn in_order<T: Send, C: FromIterator<T>>(
    items: impl rayon::iter::IndexedParallelIterator<Item = Result<T>>,
) -> Result<C> {
    let all: Vec<Result<T>> = items.collect();
    all.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    #[test]
    fn the_first_failing_item_in_order_is_the_error_whichever_fails_first() {
        // Item 2 fails late, item 6 at once: in order, item 2's error is the one.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let fail = |i: usize| Error::Job {
            path: format!("part{i}.stl").into(),
            msg: "bad".into(),
        };
        let r: Result<Vec<usize>> = pool.install(|| {
            in_order(
                (0..8usize)
                    .into_par_iter()
                    .with_max_len(1)
                    .map(|i| match i {
                        2 => {
                            std::thread::sleep(std::time::Duration::from_millis(100));
                            Err(fail(i))
                        }
                        6 => Err(fail(i)),
                        _ => Ok(i),
                    }),
            )
        });
        assert_eq!(r.unwrap_err().to_string(), "part2.stl: bad");
        let ok: Result<Vec<usize>> = in_order((0..8usize).into_par_iter().map(Ok));
        assert_eq!(ok.unwrap(), (0..8).collect::<Vec<_>>());
    }
}
