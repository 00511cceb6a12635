//! Writing a zip archive atomically: entries go into a hidden temporary sibling
//! `.NAME.tmp-PID` of the destination, which is renamed over it only when the archive is
//! complete; dropping the writer before [`ZipOut::finish`] (an error, an interrupt)
//! removes the temporary file, so a failed or interrupted run leaves nothing and an older
//! file at the path is left as it was.
//!
//! Entries are written *stored* (PNG data is already deflated; deflating it again costs
//! time and gains a few per cent at most) or *deflated* (text: manifests, settings), with
//! the zip's fixed "no date" time stamp (1980-01-01 00:00), so the same entries always give
//! the same bytes.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipWriter};

/// Size of the write buffer in front of the file, bytes.
const BUFFER_BYTES: usize = 1 << 20;

/// A zip archive being written to a temporary sibling of its destination.
pub struct ZipOut<'a> {
    dest: PathBuf,
    tmp: PathBuf,
    zip: Option<ZipWriter<BufWriter<File>>>,
    cancel: Option<&'a AtomicBool>,
}

impl std::fmt::Debug for ZipOut<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZipOut")
            .field("dest", &self.dest)
            .field("tmp", &self.tmp)
            .finish()
    }
}

/// How an entry is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Copied as is (PNG images, already compressed).
    Stored,
    /// Deflated (text).
    Deflated,
}

/// Refuses an archive at `dest` before any work is done: a path without a file name, or a
/// directory in the way.
pub fn check_dest(dest: &Path) -> Result<()> {
    let refuse = |msg: &str| Error::Bundle {
        path: dest.into(),
        msg: msg.into(),
    };
    if dest.file_name().is_none() {
        return Err(refuse("output path has no file name"));
    }
    if std::fs::symlink_metadata(dest).is_ok_and(|m| m.is_dir()) {
        return Err(refuse(
            "is a directory; refusing to replace it with an archive",
        ));
    }
    Ok(())
}

impl<'a> ZipOut<'a> {
    /// Starts an archive that will replace `dest` when finished. `dest` may be missing or
    /// a file (replaced); a directory or a path without a file name is refused. The
    /// parent directory must exist. When `cancel` is set (an interrupt), the next entry
    /// fails with [`Error::Interrupted`] and the archive is dropped.
    pub fn create(dest: &Path, cancel: Option<&'a AtomicBool>) -> Result<ZipOut<'a>> {
        check_dest(dest)?;
        remove_stale(dest);
        let tmp = crate::output::temp_sibling(dest).ok_or_else(|| Error::Bundle {
            path: dest.into(),
            msg: "not a file name".into(),
        })?;
        let file = File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
        let zip = ZipWriter::new(BufWriter::with_capacity(BUFFER_BYTES, file));
        Ok(ZipOut {
            dest: dest.to_path_buf(),
            tmp,
            zip: Some(zip),
            cancel,
        })
    }

    /// Adds entry `name` (a relative path with `/`) holding `bytes`.
    pub fn add(&mut self, name: &str, bytes: &[u8], method: Method) -> Result<()> {
        if self.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return Err(Error::Interrupted);
        }
        let options = SimpleFileOptions::default()
            .compression_method(match method {
                Method::Stored => CompressionMethod::Stored,
                Method::Deflated => CompressionMethod::Deflated,
            })
            .last_modified_time(DateTime::default())
            .unix_permissions(0o644)
            .large_file(bytes.len() as u64 >= u32::MAX as u64);
        let zip = self.zip.as_mut().expect("open until finished");
        let written = match zip.start_file(name, options) {
            Ok(()) => zip.write_all(bytes).map_err(|e| e.to_string()),
            Err(e) => Err(e.to_string()),
        };
        written.map_err(|why| self.failed(name, why))
    }

    /// The error of a failed write of entry `name`.
    fn failed(&self, name: &str, why: String) -> Error {
        Error::Bundle {
            path: self.dest.clone(),
            msg: format!("cannot write entry {name}: {why}"),
        }
    }

    /// Writes the central directory, flushes the file to disk and renames it into place.
    pub fn finish(mut self) -> Result<PathBuf> {
        let zip = self.zip.take().expect("open until finished");
        let buffered = zip.finish().map_err(|e| Error::Bundle {
            path: self.dest.clone(),
            msg: format!("cannot finish the archive: {e}"),
        })?;
        let file = buffered
            .into_inner()
            .map_err(|e| Error::io(&self.tmp, e.into_error()))?;
        drop(file);
        std::fs::rename(&self.tmp, &self.dest).map_err(|e| Error::io(&self.dest, e))?;
        Ok(self.dest.clone())
    }
}

/// Removes the temporary files `.NAME.tmp-PID` that killed runs (SIGKILL, a power cut)
/// left for `dest` ([`crate::bundle::stale_siblings`]). Best effort.
fn remove_stale(dest: &Path) {
    for (p, old, kind) in crate::bundle::stale_siblings(dest) {
        if !old && kind.is_file() {
            let _ = std::fs::remove_file(p);
        }
    }
}

impl Drop for ZipOut<'_> {
    fn drop(&mut self) {
        if self.zip.is_some() {
            self.zip = None;
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        crate::test_support::scratch("zip", tag)
    }

    use crate::test_support::names;

    #[test]
    fn writes_entries_in_order_stored_or_deflated() {
        let d = scratch("order");
        let p = d.join("a.zip");
        let mut z = ZipOut::create(&p, None).unwrap();
        z.add("job.json", b"{\"a\": 1}\n", Method::Deflated)
            .unwrap();
        z.add("masks/00000.png", &[7u8; 100], Method::Stored)
            .unwrap();
        z.finish().unwrap();
        assert_eq!(names(&d), ["a.zip"]);
        let mut a = zip::ZipArchive::new(File::open(&p).unwrap()).unwrap();
        assert_eq!(a.name_for_index(0).unwrap().unwrap(), "job.json");
        assert_eq!(a.name_for_index(1).unwrap().unwrap(), "masks/00000.png");
        let e = a.by_index(1).unwrap();
        assert_eq!(e.compression(), CompressionMethod::Stored);
        assert_eq!(e.size(), 100);
        drop(e);
        // The same entries give the same bytes.
        let first = std::fs::read(&p).unwrap();
        let mut z = ZipOut::create(&p, None).unwrap();
        z.add("job.json", b"{\"a\": 1}\n", Method::Deflated)
            .unwrap();
        z.add("masks/00000.png", &[7u8; 100], Method::Stored)
            .unwrap();
        z.finish().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), first);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn an_unfinished_archive_leaves_nothing_and_the_old_file_stays() {
        let d = scratch("drop");
        let p = d.join("a.sl1");
        std::fs::write(&p, b"old").unwrap();
        {
            let mut z = ZipOut::create(&p, None).unwrap();
            z.add("config.ini", b"x", Method::Deflated).unwrap();
        }
        assert_eq!(names(&d), ["a.sl1"]);
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        std::fs::create_dir(d.join("dir.sl1")).unwrap();
        let e = ZipOut::create(&d.join("dir.sl1"), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a directory"), "{e}");
        // An interrupt stops the archive at its next entry; nothing is left.
        let stop = AtomicBool::new(false);
        let mut z = ZipOut::create(&d.join("b.sl1"), Some(&stop)).unwrap();
        z.add("config.ini", b"x", Method::Deflated).unwrap();
        stop.store(true, Ordering::Relaxed);
        let e = z
            .add("prusaslicer.ini", b"y", Method::Deflated)
            .unwrap_err();
        assert!(matches!(e, Error::Interrupted));
        drop(z);
        assert_eq!(names(&d), ["a.sl1", "dir.sl1"]);
        let _ = std::fs::remove_dir_all(&d);
    }
}
