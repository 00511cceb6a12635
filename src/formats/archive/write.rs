//! Writing a zip archive atomically through a hidden temporary sibling `.NAME.tmp-PID`,
//! renamed over the destination only by [`ZipOut::finish`]; dropping the writer before
//! (an error, an interrupt) removes it, so an older file at the path stays as it was.
//! Entries are stored (PNG data is deflated already) or deflated (text), with the zip's
//! fixed "no date" time stamp, so the same entries always give the same bytes.
//!
//! A write that fails (a full disk) is one error naming the destination: the file goes
//! through `Quiet`, which after its first error takes every later write without doing
//! it, so the zip library's own attempt to finish an archive it is dropped with (which
//! prints to stderr when it fails) finds nothing to report.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, DateTime, ZipWriter};

/// Size of the write buffer in front of the file, bytes.
const BUFFER_BYTES: usize = 1 << 20;

/// A zip archive being written to a temporary sibling of its destination.
pub struct ZipOut<'a> {
    dest: PathBuf,
    tmp: PathBuf,
    zip: Option<ZipWriter<Quiet>>,
    /// The first write error of the file, if any.
    failed: Arc<Mutex<Option<std::io::Error>>>,
    cancel: Option<&'a AtomicBool>,
}

/// The archive's file behind a write buffer that holds the file's last bytes (from `base`)
/// and follows the position itself: the zip library asks for its position and goes back
/// to patch each entry's header once the entry is written, and those seeks and patches
/// land in the buffer instead of flushing it (a `BufWriter` flushes on every seek: about
/// eight system calls per entry). A patch of bytes already written goes to the file.
///
/// It keeps its first write error (in `failed`) and from then on only counts what it is
/// asked to write: the writes and seeks after a failure succeed (at a position kept as if
/// they had been done) without touching the file. The position is followed from the
/// start, so it is right whenever the failure comes (an error of the file, or the archive
/// dropped unfinished).
struct Quiet {
    file: File,
    /// The bytes at `base..` not written to the file yet.
    buf: Vec<u8>,
    base: u64,
    failed: Arc<Mutex<Option<std::io::Error>>>,
    /// The position, as if every write had been done.
    at: u64,
    /// The largest position reached: the end of the file.
    end: u64,
}

impl Quiet {
    fn new(file: File, failed: Arc<Mutex<Option<std::io::Error>>>) -> Quiet {
        Quiet {
            file,
            buf: Vec::with_capacity(BUFFER_BYTES),
            base: 0,
            failed,
            at: 0,
            end: 0,
        }
    }

    fn failed(&self) -> bool {
        self.failed.lock().map_or(true, |f| f.is_some())
    }

    /// Keeps `e` as the file's error unless it has one already.
    fn keep(&self, e: std::io::Error) {
        if let Ok(mut f) = self.failed.lock() {
            f.get_or_insert(e);
        }
    }

    /// Moves the position to `at`.
    fn moved(&mut self, at: u64) -> u64 {
        self.at = at;
        self.end = self.end.max(at);
        at
    }

    /// Writes `bytes` at file offset `at`.
    fn write_at(&mut self, at: u64, bytes: &[u8]) -> std::io::Result<()> {
        self.file.seek(SeekFrom::Start(at))?;
        self.file.write_all(bytes)
    }

    /// Writes the buffer to the file; it then starts where it ended.
    fn drain(&mut self) -> std::io::Result<()> {
        let buf = std::mem::take(&mut self.buf);
        let written = self.write_at(self.base, &buf);
        self.base += buf.len() as u64;
        self.buf = buf;
        self.buf.clear();
        written
    }

    /// Writes `bytes` at the position: what lies before the buffer to the file, the rest
    /// into the buffer (past its end, a gap, only once the buffer is written).
    fn put(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        let before = (self.base.saturating_sub(self.at) as usize).min(bytes.len());
        if before > 0 {
            self.write_at(self.at, &bytes[..before])?;
        }
        let (at, bytes) = (self.at + before as u64, &bytes[before..]);
        if bytes.is_empty() {
            return Ok(());
        }
        if at > self.base + self.buf.len() as u64 {
            self.drain()?;
            self.base = at;
        }
        let k = (at - self.base) as usize;
        let over = (self.buf.len() - k).min(bytes.len());
        self.buf[k..k + over].copy_from_slice(&bytes[..over]);
        self.buf.extend_from_slice(&bytes[over..]);
        if self.buf.len() >= BUFFER_BYTES {
            self.drain()?;
        }
        Ok(())
    }

    /// The file, with everything written.
    fn into_file(mut self) -> std::io::Result<File> {
        if !self.failed() {
            self.drain()?;
        }
        Ok(self.file)
    }
}

impl Write for Quiet {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if !self.failed() {
            if let Err(e) = self.put(buf) {
                self.keep(e);
            }
        }
        self.moved(self.at + buf.len() as u64);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Quiet {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let at = match to {
            SeekFrom::Start(n) => n,
            SeekFrom::Current(d) => self.at.saturating_add_signed(d),
            SeekFrom::End(d) => self.end.saturating_add_signed(d),
        };
        Ok(self.moved(at))
    }
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

/// Refuses an archive at `dest` before any work is done: a path without a file name, a
/// directory in the way, a symbolic link or a device ([`crate::output::refuse_special`]).
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
    crate::output::refuse_special(dest)
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
        let file = File::create(&tmp).map_err(|e| crate::output::write_error(dest, e))?;
        let failed = Arc::new(Mutex::new(None));
        let zip = ZipWriter::new(Quiet::new(file, failed.clone()));
        Ok(ZipOut {
            dest: dest.to_path_buf(),
            tmp,
            zip: Some(zip),
            failed,
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
        match (written, self.error()) {
            (Ok(()), None) => Ok(()),
            (_, Some(e)) => Err(Error::io(&self.dest, e)),
            (Err(why), None) => Err(Error::Bundle {
                path: self.dest.clone(),
                msg: format!("cannot write entry {name}: {why}"),
            }),
        }
    }

    /// The file's first write error (it stays failed).
    fn error(&self) -> Option<std::io::Error> {
        let mut f = self.failed.lock().ok()?;
        let e = f.take()?;
        *f = Some(std::io::Error::new(e.kind(), e.to_string()));
        Some(e)
    }

    /// Writes the central directory, flushes the file to disk and renames it into place.
    pub fn finish(mut self) -> Result<PathBuf> {
        let zip = self.zip.take().expect("open until finished");
        let finished = zip.finish().map(Quiet::into_file);
        let failed = |e: std::io::Error| {
            let _ = std::fs::remove_file(&self.tmp);
            Error::io(&self.dest, e)
        };
        match (finished, self.error()) {
            (Ok(Ok(file)), None) => drop(file),
            (_, Some(e)) => return Err(failed(e)),
            (Ok(Err(e)), None) => return Err(failed(e)),
            (Err(e), None) => return Err(failed(std::io::Error::other(e.to_string()))),
        }
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
            // The zip library finishes an archive it is dropped with: into nothing.
            if let Ok(mut f) = self.failed.lock() {
                f.get_or_insert_with(|| std::io::Error::other("dropped"));
            }
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
        let write = || {
            let mut z = ZipOut::create(&p, None).unwrap();
            z.add("job.json", b"{\"a\": 1}\n", Method::Deflated)
                .unwrap();
            z.add("masks/00000.png", &[7u8; 100], Method::Stored)
                .unwrap();
            z.finish().unwrap();
        };
        write();
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
        write();
        assert_eq!(std::fs::read(&p).unwrap(), first);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn the_buffer_writes_what_the_zip_library_writes_to_a_file() {
        // Small entries (their headers patched in the buffer), entries bigger than the
        // buffer (patched in the file) and a deflated one, against the zip library on a
        // plain file.
        let d = scratch("patched");
        let mut bits = crate::test_support::xorshift_bits(0x21b_5eed);
        let entries: Vec<(String, Vec<u8>, Method)> = [
            10,
            5000,
            3 * BUFFER_BYTES / 2,
            7,
            BUFFER_BYTES - 40,
            0,
            2 * BUFFER_BYTES + 3,
        ]
        .iter()
        .enumerate()
        .map(|(i, &n)| {
            let bytes: Vec<u8> = (0..n).map(|_| bits() as u8).collect();
            let method = [Method::Stored, Method::Deflated][(i == 3) as usize];
            (format!("e{i}.bin"), bytes, method)
        })
        .collect();
        let ours = d.join("ours.zip");
        let mut z = ZipOut::create(&ours, None).unwrap();
        for (name, bytes, method) in &entries {
            z.add(name, bytes, *method).unwrap();
        }
        z.finish().unwrap();
        let theirs = d.join("theirs.zip");
        let mut z = ZipWriter::new(File::create(&theirs).unwrap());
        for (name, bytes, method) in &entries {
            let options = SimpleFileOptions::default()
                .compression_method(match method {
                    Method::Stored => CompressionMethod::Stored,
                    Method::Deflated => CompressionMethod::Deflated,
                })
                .last_modified_time(DateTime::default())
                .unix_permissions(0o644);
            z.start_file(name.as_str(), options).unwrap();
            z.write_all(bytes).unwrap();
        }
        z.finish().unwrap();
        assert!(std::fs::read(&ours).unwrap() == std::fs::read(&theirs).unwrap());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn the_buffer_writes_what_a_file_would_hold() {
        // Appends, patches before, across and inside the buffer, seeks past the end.
        let d = scratch("quiet");
        let mut bits = crate::test_support::xorshift_bits(0x0a11_5eed);
        let mut rnd = |n: u64| bits() % n.max(1);
        let path = d.join("q.bin");
        let failed = Arc::new(Mutex::new(None));
        let mut q = Quiet::new(File::create(&path).unwrap(), failed.clone());
        let mut want = std::io::Cursor::new(Vec::new());
        for _ in 0..400 {
            let end = want.get_ref().len() as u64;
            let to = match rnd(4) {
                0 => SeekFrom::Start(rnd(end + 1)),
                1 => SeekFrom::End(-(rnd(end.min(BUFFER_BYTES as u64 * 2) + 1) as i64)),
                2 => SeekFrom::Current(0),
                _ => SeekFrom::End(rnd(3) as i64),
            };
            assert_eq!(q.seek(to).unwrap(), want.seek(to).unwrap());
            let n = [rnd(40), rnd(5000), rnd(BUFFER_BYTES as u64 / 3)][rnd(3) as usize];
            let bytes: Vec<u8> = (0..n).map(|_| rnd(256) as u8).collect();
            q.write_all(&bytes).unwrap();
            want.write_all(&bytes).unwrap();
        }
        assert!(failed.lock().unwrap().is_none());
        drop(q.into_file().unwrap());
        assert!(std::fs::read(&path).unwrap() == want.into_inner());
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
