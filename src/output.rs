//! Writing output files (plots, pictures, traces, calibrations) so that a reader never sees
//! half a file: each is written to a hidden temporary sibling, `.NAME.tmp-PID`, and renamed
//! over the destination once complete. Bundles, which are directories, have their own
//! writer (`bundle::BundleWriter`), and so do one-file jobs (`formats::archive::write`).
//!
//! A reader sees the old file or the whole new one; a failed write leaves nothing, and an
//! error names the output, never the temporary file.
//!
//! One rule for every output, bundles and one-file jobs included: a symbolic link or a
//! special file (a device such as `/dev/null`, a FIFO, a socket) at the output path is
//! refused ([`refuse_special`]). Renaming a new file over it would replace the link or the
//! device node itself, not what it leads to, and writing through it would not be atomic;
//! for a link, the path it points to is the output to give.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The temporary sibling (`.NAME.tmp-PID`) a file is written to before it is renamed into
/// place, or `None` when `path` has no file name.
pub fn temp_sibling(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?;
    Some(path.with_file_name(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    )))
}

/// What is wrong with the directory an output at `path` goes in, if anything: it does
/// not exist, or it is not a directory (a file of that name).
pub fn parent_problem(path: &Path) -> Option<String> {
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty())?;
    if parent.is_dir() {
        None
    } else if parent.exists() {
        Some(format!("{} is not a directory", parent.display()))
    } else {
        Some(format!("directory {} does not exist", parent.display()))
    }
}

/// The error of a failed write of the output `path` (through its temporary sibling):
/// naming `path`, the I/O error said as [`parent_problem`] when there is one (its kind,
/// and so the error's code, kept).
pub fn write_error(path: &Path, e: std::io::Error) -> Error {
    match parent_problem(path) {
        Some(msg) => Error::io(path, std::io::Error::new(e.kind(), msg)),
        None => Error::io(path, e),
    }
}

/// Refuses an output at `path` that is a symbolic link, naming where it points, or a
/// special file, naming its kind (see the module docs).
pub fn refuse_special(path: &Path) -> Result<()> {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    let t = meta.file_type();
    if !t.is_symlink() {
        return match special_kind(&t) {
            None => Ok(()),
            Some(kind) => Err(Error::Bundle {
                path: path.into(),
                msg: format!("is {kind}, not a file; refusing to replace it"),
            }),
        };
    }
    let to = std::fs::read_link(path)
        .map(|t| format!(" (to {})", t.display()))
        .unwrap_or_default();
    Err(Error::Bundle {
        path: path.into(),
        msg: format!("is a symbolic link{to}; refusing to replace it (to replace what it points to, give that path as the output)"),
    })
}

/// What a special file is (`a character device`, ...), or `None` for a file or a directory.
fn special_kind(t: &std::fs::FileType) -> Option<&'static str> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let kinds = [
            (t.is_char_device(), "a character device"),
            (t.is_block_device(), "a block device"),
            (t.is_fifo(), "a FIFO"),
            (t.is_socket(), "a socket"),
        ];
        if let Some((_, kind)) = kinds.into_iter().find(|k| k.0) {
            return Some(kind);
        }
    }
    (!t.is_file() && !t.is_dir()).then_some("a special file")
}

/// Writes `bytes` to `path` through a temporary sibling renamed into place; on failure
/// the temporary file is removed and `path` is left as it was. A symbolic link at `path`
/// is refused ([`refuse_special`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_sibling(path)
        .ok_or_else(|| Error::Usage(format!("{}: not a file name", path.display())))?;
    refuse_special(path)?;
    std::fs::write(&tmp, bytes)
        .and_then(|_| std::fs::rename(&tmp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            write_error(path, e)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_files_and_leaves_nothing_on_failure() {
        let dir = crate::test_support::scratch("output", "atomic");
        let p = dir.join("a.png");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        // A destination that cannot be replaced (a non-empty directory).
        std::fs::create_dir_all(dir.join("d.png/x")).unwrap();
        assert!(write_atomic(&dir.join("d.png"), b"x").is_err());
        assert_eq!(crate::test_support::names(&dir), ["a.png", "d.png"]);
        // A link at the path is refused; what it points to stays.
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink("a.png", dir.join("l.png")).unwrap();
            let e = write_atomic(&dir.join("l.png"), b"x")
                .unwrap_err()
                .to_string();
            assert!(e.ends_with("l.png: is a symbolic link (to a.png); refusing to replace it (to replace what it points to, give that path as the output)"), "{e}");
            assert_eq!(std::fs::read(dir.join("a.png")).unwrap(), b"two");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
