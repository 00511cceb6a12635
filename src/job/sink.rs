//! Where a job's files go while it is made: the bundle writer's staging directory (the
//! directory bundle), or, for the one-file forms, memory (spilling to an unlinked
//! temporary file beside the output past [`MEMORY_BUDGET`] bytes, so memory stays bounded
//! however many layers), from where `export` writes the file whole, in layer order, once
//! the job is planned and replays clean.

use crate::bundle::BundleSource;
use crate::bundle::BundleWriter;
use crate::error::{Error, Result};
use std::borrow::Cow;
use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Bytes of files a one-file job keeps in memory; later files go to the spill file (a
/// default job's masks take 5–15 MB).
pub(super) const MEMORY_BUDGET: u64 = 64 << 20;

/// Where one file is kept.
enum Stored {
    Memory(Vec<u8>),
    /// In the spill file: offset and length.
    Spilled(u64, u64),
}

/// The files of a one-file job.
#[derive(Default)]
pub(super) struct Kept {
    files: HashMap<String, Stored>,
    in_memory: u64,
    /// The spill file (its position is shared: a read seeks and reads under the lock).
    spill: Option<Mutex<File>>,
    spill_len: u64,
}

/// The files of a job being made.
pub(super) enum Sink {
    /// A bundle directory's staging directory.
    Dir(BundleWriter),
    /// Memory (and a spill file): the output path names the files in messages.
    Memory { out: PathBuf, kept: Mutex<Kept> },
}

impl Sink {
    /// Files kept for the one-file output `out`.
    pub(super) fn memory(out: &Path) -> Sink {
        Sink::Memory {
            out: out.into(),
            kept: Mutex::new(Kept::default()),
        }
    }

    /// Creates a subdirectory (relative path) for files to come.
    pub(super) fn create_dir(&self, rel: &str) -> Result<()> {
        match self {
            Sink::Dir(w) => w.create_dir(rel),
            Sink::Memory { .. } => Ok(()),
        }
    }

    /// Writes a file (relative path).
    pub(super) fn write_file(&self, rel: &str, bytes: &[u8]) -> Result<()> {
        match self {
            Sink::Dir(w) => w.write_file(rel, bytes),
            Sink::Memory { out, kept } => {
                let mut k = kept.lock().unwrap_or_else(|e| e.into_inner());
                k.put(out, rel, bytes, MEMORY_BUDGET)
            }
        }
    }
}

impl BundleSource for Sink {
    /// A file written so far (the cure prediction reads the masks back).
    fn read(&self, rel: &str) -> std::io::Result<Cow<'_, [u8]>> {
        match self {
            Sink::Dir(w) => crate::bundle::DirSource::new(w.staging_dir())
                .read(rel)
                .map(|b| Cow::Owned(b.into_owned())),
            Sink::Memory { kept, .. } => {
                let k = kept.lock().unwrap_or_else(|e| e.into_inner());
                k.read(rel).map(|b| Cow::Owned(b.into_owned()))
            }
        }
    }

    fn shown(&self, rel: &str) -> PathBuf {
        match self {
            Sink::Dir(w) => w.staging_dir().join(rel),
            Sink::Memory { out, .. } => out.join(rel),
        }
    }
}

impl Kept {
    /// The bytes of file `rel` (those in memory not copied).
    fn read(&self, rel: &str) -> std::io::Result<Cow<'_, [u8]>> {
        match self.files.get(rel) {
            Some(Stored::Memory(b)) => Ok(Cow::Borrowed(b)),
            Some(&Stored::Spilled(at, n)) => {
                let mut f = self
                    .spill
                    .as_ref()
                    .expect("spilled files have a spill file")
                    .lock()
                    .unwrap_or_else(|e| e.into_inner());
                let mut buf = vec![0; n as usize];
                f.seek(SeekFrom::Start(at))
                    .and_then(|_| f.read_exact(&mut buf))?;
                Ok(Cow::Owned(buf))
            }
            None => Err(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("{rel} was not made"),
            )),
        }
    }

    /// Keeps `bytes` as file `rel` (in place of a file of that name written before): in
    /// memory while under `budget`, else in the spill file (created beside `out` and, on
    /// Unix, unlinked at once).
    fn put(&mut self, out: &Path, rel: &str, bytes: &[u8], budget: u64) -> Result<()> {
        if let Some(Stored::Memory(old)) = self.files.get(rel) {
            self.in_memory -= old.len() as u64;
        }
        let n = bytes.len() as u64;
        let stored = if self.in_memory + n <= budget {
            self.in_memory += n;
            Stored::Memory(bytes.to_vec())
        } else {
            if self.spill.is_none() {
                self.spill = Some(Mutex::new(spill_file(out)?));
            }
            let f = self
                .spill
                .as_mut()
                .expect("just made")
                .get_mut()
                .unwrap_or_else(|e| e.into_inner());
            let at = self.spill_len;
            f.seek(SeekFrom::Start(at))
                .and_then(|_| f.write_all(bytes))
                .map_err(|e| Error::io(out, e))?;
            self.spill_len += n;
            Stored::Spilled(at, n)
        };
        self.files.insert(rel.to_string(), stored);
        Ok(())
    }
}

/// A new temporary file beside `out`, already unlinked.
fn spill_file(out: &Path) -> Result<File> {
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = format!(
        ".{}.spill-{}",
        out.file_name()
            .map_or("job".into(), |n| n.to_string_lossy()),
        std::process::id()
    );
    let path = dir.join(name);
    let f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&path)
        .map_err(|e| Error::io(&path, e))?;
    // Unlinked now (Unix), so it never outlives the process; elsewhere it stays as
    // `.NAME.spill-PID` beside the output.
    #[cfg(unix)]
    let _ = std::fs::remove_file(&path);
    Ok(f)
}

/// The files a [`Sink::Memory`] kept, read back for the exporter.
pub(super) struct MemoryFiles {
    out: PathBuf,
    kept: Kept,
}

impl MemoryFiles {
    /// The files `kept` for the output `out`.
    pub(super) fn new(out: &Path, kept: Mutex<Kept>) -> MemoryFiles {
        MemoryFiles {
            out: out.into(),
            kept: kept.into_inner().unwrap_or_else(|e| e.into_inner()),
        }
    }
}

impl BundleSource for MemoryFiles {
    fn read(&self, rel: &str) -> std::io::Result<Cow<'_, [u8]>> {
        self.kept.read(rel)
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.out.join(rel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_past_the_budget_spill_and_read_back_the_same() {
        let dir = std::env::temp_dir().join(format!("dmdsl-sink-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("a.sl1");
        let mut k = Kept::default();
        let files: Vec<(String, Vec<u8>)> = (0..20)
            .map(|i| (format!("masks/{i:05}.png"), vec![i as u8; 100 + i]))
            .collect();
        for (rel, b) in &files {
            k.put(&out, rel, b, 1000).unwrap();
        }
        assert!(k.spill.is_some() && k.in_memory <= 1000);
        let m = MemoryFiles::new(&out, Mutex::new(k));
        for (rel, b) in &files {
            assert_eq!(&*m.read(rel).unwrap(), b.as_slice());
        }
        assert!(m.read("masks/99999.png").is_err());
        // The spill file is already gone from the directory.
        if cfg!(unix) {
            assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_file_written_again_replaces_the_first_and_its_share_of_the_budget() {
        let out = std::env::temp_dir().join("never-made.sl1");
        let mut k = Kept::default();
        for round in 0..5u8 {
            k.put(&out, "masks/00000.png", &[round; 600], 1000).unwrap();
        }
        // Five writes of 600 bytes fit a budget of 1000: each replaced the last.
        assert!(k.spill.is_none());
        assert_eq!(k.in_memory, 600);
        assert_eq!(&*k.read("masks/00000.png").unwrap(), &[4u8; 600][..]);
    }
}
