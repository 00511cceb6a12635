//! Where a job's files go while it is made: the bundle writer's staging directory (the
//! directory bundle), or memory, for the one-file forms (`export`), which are written
//! whole, in layer order, once the job is planned and replays clean.

use crate::bundle::BundleWriter;
use crate::error::{Error, Result};
use crate::export::BundleFiles;
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The files of a job being made.
pub(super) enum Sink {
    /// A bundle directory's staging directory.
    Dir(BundleWriter),
    /// Memory: the files by relative path (the output path names them in messages).
    Memory {
        out: PathBuf,
        files: Mutex<HashMap<String, Vec<u8>>>,
    },
}

impl Sink {
    /// Files kept in memory for the one-file output `out`.
    pub(super) fn memory(out: &Path) -> Sink {
        Sink::Memory {
            out: out.into(),
            files: Mutex::new(HashMap::new()),
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
            Sink::Memory { files, .. } => {
                files
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .insert(rel.to_string(), bytes.to_vec());
                Ok(())
            }
        }
    }
}

/// The files a [`Sink::Memory`] holds, read back for the exporter.
pub(super) struct MemoryFiles {
    pub out: PathBuf,
    pub files: HashMap<String, Vec<u8>>,
}

impl BundleFiles for MemoryFiles {
    fn read(&self, rel: &str) -> Result<Cow<'_, [u8]>> {
        self.files
            .get(rel)
            .map(|b| Cow::Borrowed(b.as_slice()))
            .ok_or_else(|| Error::Bundle {
                path: self.out.clone(),
                msg: format!("{rel} was not made"),
            })
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.out.join(rel)
    }
}
