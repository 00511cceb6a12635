//! Reading input files: meshes, profiles, tables, calibrations, manifests.
//!
//! Each is read whole, and only from a regular file (or a link to one): a directory, a
//! FIFO, a socket or a device is refused by name before it is opened (opening a FIFO would
//! block until a writer comes; a device may never end), and a file larger than the bound
//! given for its kind is refused before it is read.

use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

/// The largest mesh file read, bytes (4 GiB: about 80 million binary STL triangles).
pub const MESH_MAX_BYTES: u64 = 1 << 32;
/// The largest text input read (profile, calibration, table, manifest), bytes.
pub const TEXT_MAX_BYTES: u64 = 1 << 28;

/// Reads the whole file at `path`, a `what` (e.g. "mesh file"), of at most `max_bytes`.
pub fn read_file(path: &Path, what: &str, max_bytes: u64) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_dir() {
        return Err(Error::input(path, format!("is a directory, not a {what}")));
    }
    if !meta.is_file() {
        return Err(Error::input(
            path,
            format!("is not a regular file (a pipe, socket or device), not a {what}"),
        ));
    }
    if meta.len() > max_bytes {
        return Err(Error::input(
            path,
            format!(
                "is {} bytes, more than the {max_bytes} bytes a {what} may have",
                meta.len()
            ),
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    // A file that grows while it is read is cut at the bound and refused.
    file.take(max_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > max_bytes {
        return Err(Error::input(
            path,
            format!("grew beyond the {max_bytes} bytes a {what} may have while it was read"),
        ));
    }
    Ok(bytes)
}

/// Reads the UTF-8 text file at `path`, a `what`, of at most [`TEXT_MAX_BYTES`].
pub fn read_text(path: &Path, what: &str) -> Result<String> {
    let bytes = read_file(path, what, TEXT_MAX_BYTES)?;
    String::from_utf8(bytes).map_err(|_| Error::input(path, format!("not UTF-8 text (a {what})")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_only_and_within_the_bound() {
        let dir = crate::test_support::scratch("input", "files");
        let f = dir.join("a.txt");
        std::fs::write(&f, "hello").unwrap();
        assert_eq!(read_file(&f, "table", 5).unwrap(), b"hello");
        assert_eq!(read_text(&f, "table").unwrap(), "hello");
        let e = read_file(&f, "table", 4).unwrap_err().to_string();
        assert!(
            e.ends_with("a.txt: is 5 bytes, more than the 4 bytes a table may have"),
            "{e}"
        );
        let e = read_file(&dir, "mesh file", 10).unwrap_err().to_string();
        assert!(e.ends_with("is a directory, not a mesh file"), "{e}");
        #[cfg(unix)]
        {
            let e = read_file(Path::new("/dev/zero"), "mesh file", 10)
                .unwrap_err()
                .to_string();
            assert!(e.contains("is not a regular file"), "{e}");
        }
        std::fs::write(&f, [0xff, 0xfe]).unwrap();
        let e = read_text(&f, "profile").unwrap_err().to_string();
        assert!(e.ends_with("not UTF-8 text (a profile)"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
