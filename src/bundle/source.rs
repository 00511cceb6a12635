//! Where a bundle's files come from: a directory, or memory (a zipped bundle, or a job
//! imported from another format), behind one trait, so the executor and `inspect` read
//! every form the same way.

use std::borrow::Cow;
use std::collections::HashMap;
use std::io;
use std::path::{Component, Path, PathBuf};

/// The files of a bundle, by the relative paths its manifest names (`masks/00012.png`).
pub trait BundleSource: Sync + Send {
    /// The bytes of file `rel`. An absent file is an [`io::ErrorKind::NotFound`] error; a
    /// path that is not relative and inside the bundle is an
    /// [`io::ErrorKind::InvalidInput`] error.
    fn read(&self, rel: &str) -> io::Result<Cow<'_, [u8]>>;

    /// How file `rel` is named in messages (`part.dmdjob/masks/00012.png`,
    /// `part.sl1/part00012.png`).
    fn shown(&self, rel: &str) -> PathBuf;

    /// [`BundleSource::read`] with an error naming the file ([`shown`](Self::shown)).
    fn file(&self, rel: &str) -> crate::error::Result<Cow<'_, [u8]>> {
        self.read(rel)
            .map_err(|e| crate::error::Error::io(self.shown(rel), e))
    }
}

/// A relative path made only of plain components (nothing outside the bundle).
pub fn is_inside(rel: &str) -> bool {
    !rel.is_empty()
        && Path::new(rel)
            .components()
            .all(|c| matches!(c, Component::Normal(_)))
}

fn outside(rel: &str) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("path {rel:?} leads outside the bundle"),
    )
}

/// The files of a bundle directory.
#[derive(Debug, Clone)]
pub struct DirSource {
    dir: PathBuf,
}

impl DirSource {
    /// The files under bundle directory `dir`.
    pub fn new(dir: &Path) -> DirSource {
        DirSource { dir: dir.into() }
    }
}

impl BundleSource for DirSource {
    fn read(&self, rel: &str) -> io::Result<Cow<'_, [u8]>> {
        if !is_inside(rel) {
            return Err(outside(rel));
        }
        std::fs::read(self.dir.join(rel)).map(Cow::Owned)
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.dir.join(rel)
    }
}

/// Files held in memory, by name: a zipped bundle's entries, or the masks of a job
/// imported from another format under the names its manifest gives them.
#[derive(Debug, Clone, Default)]
pub struct MemSource {
    path: PathBuf,
    files: HashMap<String, Vec<u8>>,
}

impl MemSource {
    /// The files `files` of the archive or file at `path` (named in messages).
    pub fn new(path: &Path, files: HashMap<String, Vec<u8>>) -> MemSource {
        MemSource {
            path: path.into(),
            files,
        }
    }
}

impl BundleSource for MemSource {
    fn read(&self, rel: &str) -> io::Result<Cow<'_, [u8]>> {
        if !is_inside(rel) {
            return Err(outside(rel));
        }
        // The manifest may name a file `masks//a.png` or `masks/./a.png`; the archive
        // holds it as `masks/a.png`.
        let key: Vec<&str> = rel
            .split('/')
            .filter(|c| !c.is_empty() && *c != ".")
            .collect();
        self.files
            .get(&key.join("/"))
            .map(|b| Cow::Borrowed(b.as_slice()))
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "not in the archive"))
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.path.join(rel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_sources_refuse_paths_leading_outside() {
        assert!(is_inside("masks/00001.png"));
        assert!(!is_inside("../x.png"));
        assert!(!is_inside("/etc/passwd"));
        assert!(!is_inside(""));
        let d = DirSource::new(Path::new("/nonexistent-bundle"));
        let m = MemSource::new(
            Path::new("x.zip"),
            HashMap::from([("masks/a.png".to_string(), vec![1, 2])]),
        );
        for s in [&d as &dyn BundleSource, &m] {
            let e = s.read("../x.png").unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        }
        assert_eq!(&*m.read("masks/./a.png").unwrap(), &[1, 2]);
        assert_eq!(
            m.read("masks/b.png").unwrap_err().kind(),
            io::ErrorKind::NotFound
        );
        assert_eq!(m.shown("masks/a.png"), Path::new("x.zip/masks/a.png"));
    }
}
