//! Writing output files (plots, pictures, traces, calibrations) so that a reader never sees
//! half a file: each is written to a hidden temporary sibling, `.NAME.tmp-PID`, and renamed
//! over the destination once complete. Bundles, which are directories, have their own
//! writer (`bundle::BundleWriter`).
//!
//! A reader sees the old file or the whole new one; a failed write leaves nothing.

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

/// Writes `bytes` to `path` through a temporary sibling renamed into place; on failure
/// the temporary file is removed and `path` is left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_sibling(path)
        .ok_or_else(|| Error::Usage(format!("{}: not a file name", path.display())))?;
    std::fs::write(&tmp, bytes)
        .and_then(|_| std::fs::rename(&tmp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            Error::io(path, e)
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
        let _ = std::fs::remove_dir_all(&dir);
    }
}
