//! Reading a zip archive from elsewhere, safely, without extracting anything to the
//! disk (docs/EXECUTOR.md, "What it reads", lists what is refused).
//!
//! An archive is input like any other file, so it is read as if hostile: its central
//! directory is checked when it is opened, against [`Limits`], and each refusal is one line
//! naming the archive and the entry ([`Error::Archive`]); directory entries are checked and
//! then left out. Entries are inflated into memory only when a reader asks for them: the
//! settings once, kept ([`Archive::get`]); an image at each read, not kept
//! ([`Archive::read`], [`Archive::into_source`]). Declared sizes are not trusted: an entry
//! that does not inflate to exactly its declared size, or fails its CRC, is refused when
//! it is read.

use crate::bundle::BundleSource;
use crate::error::{Error, Result};
use std::borrow::Cow;
use std::collections::HashMap;
use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

/// Bounds on what an archive may hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest archive file, bytes.
    pub max_archive_bytes: u64,
    /// Most entries (directories included).
    pub max_entries: usize,
    /// Largest uncompressed entry, bytes.
    pub max_entry_bytes: u64,
    /// Largest sum of the uncompressed entries, bytes.
    pub max_total_bytes: u64,
}

impl Default for Limits {
    /// 4 GiB archives, 200,000 entries, 256 MiB an entry, 4 GiB in all: a million-pixel
    /// mask is at most about 1 MiB as PNG, so a job of 100,000 layers fits.
    fn default() -> Self {
        Limits {
            max_archive_bytes: 1 << 32,
            max_entries: 200_000,
            max_entry_bytes: 1 << 28,
            max_total_bytes: 1 << 32,
        }
    }
}

/// The archive's bytes, shared by every reader of its entries.
#[derive(Debug, Clone)]
struct Bytes(Arc<Vec<u8>>);

impl AsRef<[u8]> for Bytes {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// One file of the archive: its index in the zip, its declared size, and its bytes once a
/// reader asked for them with [`Archive::get`].
#[derive(Debug)]
struct Entry {
    index: usize,
    size: u64,
    kept: OnceLock<Vec<u8>>,
}

/// The files of an archive, inflated as they are read.
#[derive(Debug)]
pub struct Archive {
    /// The archive's path, for messages.
    path: PathBuf,
    /// File names in archive order (directories left out).
    names: Vec<String>,
    /// The files by name.
    entries: HashMap<String, Entry>,
    /// The zip over the archive's bytes (cloned for each read: the bytes are shared).
    zip: zip::ZipArchive<Cursor<Bytes>>,
}

impl Archive {
    /// The archive's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file names in archive order (no directories).
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Whether the archive holds file `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.entries.contains_key(name)
    }

    /// The contents of file `name` (`None` when the archive has none), inflated the first
    /// time and kept: for the settings a reader parses. An entry that does not inflate to
    /// its declared size is an error naming it.
    pub fn get(&self, name: &str) -> Result<Option<&[u8]>> {
        let Some(e) = self.entries.get(name) else {
            return Ok(None);
        };
        if let Some(b) = e.kept.get() {
            return Ok(Some(b));
        }
        let b = self.inflate(e).map_err(|msg| self.error(Some(name), msg))?;
        Ok(Some(e.kept.get_or_init(|| b)))
    }

    /// The contents of file `name`, inflated now and not kept (an image a job reads once
    /// or twice). A missing file is an [`std::io::ErrorKind::NotFound`] error, one that
    /// does not inflate to its declared size an [`std::io::ErrorKind::InvalidData`] one.
    pub fn read(&self, name: &str) -> std::io::Result<Vec<u8>> {
        use std::io::{Error as IoError, ErrorKind};
        let e = self
            .entries
            .get(name)
            .ok_or_else(|| IoError::new(ErrorKind::NotFound, "not in the archive"))?;
        match e.kept.get() {
            Some(b) => Ok(b.clone()),
            None => self
                .inflate(e)
                .map_err(|m| IoError::new(ErrorKind::InvalidData, m)),
        }
    }

    /// Inflates entry `e`, never past its declared size, checking its size and CRC.
    fn inflate(&self, e: &Entry) -> std::result::Result<Vec<u8>, String> {
        let mut zip = self.zip.clone();
        let f = zip
            .by_index(e.index)
            .map_err(|err| format!("cannot be read: {err}"))?;
        // Grows as it is read: the declared size is not trusted for the allocation either.
        let mut data = Vec::with_capacity(e.size.min(1 << 20) as usize);
        // Reading to the end (one byte past the declared size at most) also checks the CRC.
        f.take(e.size + 1)
            .read_to_end(&mut data)
            .map_err(|err| format!("does not inflate: {err}"))?;
        if data.len() as u64 != e.size {
            let got = match data.len() as u64 > e.size {
                true => format!("more than {}", e.size),
                false => data.len().to_string(),
            };
            return Err(format!(
                "inflates to {got} bytes, its header declares {}",
                e.size
            ));
        }
        Ok(data)
    }

    /// The archive's files under folder `dir` (empty, or ending in `/`), by the names
    /// they have there, as a job's files (`path/dir/NAME` in messages).
    pub fn into_source(self, dir: &str) -> ArchiveFiles {
        ArchiveFiles {
            shown: self.path.join(dir),
            dir: dir.to_string(),
            archive: self,
        }
    }

    /// An error about entry `entry` of this archive.
    pub fn error(&self, entry: Option<&str>, msg: impl Into<String>) -> Error {
        Error::Archive {
            path: self.path.clone(),
            entry: entry.map(str::to_string),
            msg: msg.into(),
        }
    }
}

/// A job's files in an archive ([`Archive::into_source`]), each inflated when it is read.
#[derive(Debug)]
pub struct ArchiveFiles {
    archive: Archive,
    dir: String,
    shown: PathBuf,
}

impl BundleSource for ArchiveFiles {
    fn read(&self, rel: &str) -> std::io::Result<Cow<'_, [u8]>> {
        if !crate::bundle::is_inside(rel) {
            let msg = format!("path {rel:?} leads outside the bundle");
            return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, msg));
        }
        // The manifest may name a file `masks//a.png` or `masks/./a.png`; the archive
        // holds it as `masks/a.png`.
        let key: Vec<&str> = rel
            .split('/')
            .filter(|c| !c.is_empty() && *c != ".")
            .collect();
        let name = format!("{}{}", self.dir, key.join("/"));
        self.archive.read(&name).map(Cow::Owned)
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.shown.join(rel)
    }
}

/// True when `bytes` start like a zip archive (a local file header, or the end record of
/// an empty archive).
pub fn looks_like_zip(bytes: &[u8]) -> bool {
    bytes.starts_with(b"PK\x03\x04") || bytes.starts_with(b"PK\x05\x06")
}

/// Opens the archive whose bytes are `bytes` (`path` names it in messages): its central
/// directory read and checked, nothing inflated.
pub fn read_zip(path: &Path, bytes: Vec<u8>, limits: &Limits) -> Result<Archive> {
    let error = |entry: Option<&str>, msg: String| Error::Archive {
        path: path.into(),
        entry: entry.map(str::to_string),
        msg,
    };
    let bytes = Bytes(Arc::new(bytes));
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes.clone()))
        .map_err(|e| error(None, format!("not a readable zip archive: {e}")))?;
    if zip.len() > limits.max_entries {
        let msg = format!(
            "{} entries, more than the {} this reader accepts",
            zip.len(),
            limits.max_entries
        );
        return Err(error(None, msg));
    }
    // The zip crate keeps one entry per name: a name listed twice shows in the central
    // directory itself.
    if let Some(dup) = duplicate_name(bytes.as_ref(), zip.len()) {
        return Err(error(
            Some(&dup),
            "the name appears twice in the archive".into(),
        ));
    }
    let files = declared(&mut zip, limits).map_err(|(at, msg)| error(at.as_deref(), msg))?;
    let mut archive = Archive {
        path: path.into(),
        names: Vec::with_capacity(files.len()),
        entries: HashMap::with_capacity(files.len()),
        zip,
    };
    for (index, name, size) in files {
        let kept = OnceLock::new();
        archive.names.push(name.clone());
        archive.entries.insert(name, Entry { index, size, kept });
    }
    Ok(archive)
}

/// What is wrong with an archive: the entry, if one, and what.
type Refusal = (Option<String>, String);

/// The files of `zip` as (index, name, declared size), read from the central directory
/// and checked (names, kinds, methods, declared sizes within `limits`) before anything is
/// inflated.
fn declared(
    zip: &mut zip::ZipArchive<Cursor<Bytes>>,
    limits: &Limits,
) -> std::result::Result<Vec<(usize, String, u64)>, Refusal> {
    let mut entries = Vec::with_capacity(zip.len());
    let mut seen = HashMap::with_capacity(zip.len());
    let mut total: u64 = 0;
    for i in 0..zip.len() {
        let f = zip
            .by_index_raw(i)
            .map_err(|e| (None, format!("entry {i} cannot be read: {e}")))?;
        let Ok(name) = std::str::from_utf8(f.name_raw()).map(str::to_string) else {
            let shown = String::from_utf8_lossy(f.name_raw()).into_owned();
            return Err((Some(shown), "name is not UTF-8".into()));
        };
        let bad = |msg: String| (Some(name.clone()), msg);
        check_name(&name).map_err(bad)?;
        if let Some(first) = seen.insert(name.trim_end_matches('/').to_string(), i) {
            return Err(bad(format!(
                "the name appears twice (entries {first} and {i})"
            )));
        }
        let method = f.compression();
        let size = f.size();
        total = total.saturating_add(size);
        let problem = if f.encrypted() {
            "entry is encrypted".into()
        } else if f.is_symlink() {
            "entry is a symbolic link".into()
        } else if !matches!(
            method,
            zip::CompressionMethod::Stored | zip::CompressionMethod::Deflated
        ) {
            format!("compression method {method} is not supported (stored or deflated only)")
        } else if size > limits.max_entry_bytes {
            format!(
                "declared size {size} bytes is above the {} bytes an entry may hold",
                limits.max_entry_bytes
            )
        } else if total > limits.max_total_bytes {
            format!(
                "the entries so far declare {total} bytes, above the {} bytes an archive may hold",
                limits.max_total_bytes
            )
        } else {
            String::new()
        };
        if !problem.is_empty() {
            return Err(bad(problem));
        }
        if !name.ends_with('/') {
            entries.push((i, name, size));
        }
    }
    Ok(entries)
}

/// A name the central directory of the zip `bytes` lists twice, when it lists more
/// entries than the `distinct` names the zip crate kept (archives whose end record gives
/// the count: not zip64).
fn duplicate_name(bytes: &[u8], distinct: usize) -> Option<String> {
    let u16_at = |i: usize| {
        bytes
            .get(i..i + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]) as usize)
    };
    let u32_at = |i: usize| {
        bytes
            .get(i..i + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let lo = bytes.len().saturating_sub(22 + 65535);
    let end = (lo..bytes.len().saturating_sub(21))
        .rev()
        .find(|&i| bytes[i..].starts_with(b"PK\x05\x06"))?;
    let count = u16_at(end + 10)?;
    if count == 0xFFFF || count <= distinct {
        return None;
    }
    let mut at = u32_at(end + 16)?;
    let mut seen = std::collections::HashSet::new();
    for _ in 0..count {
        if !bytes.get(at..)?.starts_with(b"PK\x01\x02") {
            return None;
        }
        let (n, x, c) = (u16_at(at + 28)?, u16_at(at + 30)?, u16_at(at + 32)?);
        let name = String::from_utf8_lossy(bytes.get(at + 46..at + 46 + n)?).into_owned();
        if !seen.insert(name.clone()) {
            return Some(name);
        }
        at += 46 + n + x + c;
    }
    None
}

/// Checks an entry name: relative, `/`-separated, every component a plain name.
fn check_name(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() {
        return Err("empty name".into());
    }
    if name.contains('\\') {
        return Err("name holds a backslash".into());
    }
    if name.contains('\0') {
        return Err("name holds a NUL byte".into());
    }
    if name.starts_with('/') {
        return Err("absolute path".into());
    }
    let body = name.strip_suffix('/').unwrap_or(name);
    for c in body.split('/') {
        match c {
            "" => return Err("name has an empty component (`//`)".into()),
            "." | ".." => return Err(format!("name has a `{c}` component")),
            _ if c.len() >= 2 && c.as_bytes()[1] == b':' => {
                return Err("name starts with a drive letter".into())
            }
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn zip_of(names: &[&str]) -> Vec<u8> {
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        for n in names {
            w.start_file(*n, zip::write::SimpleFileOptions::default())
                .unwrap();
            w.write_all(n.as_bytes()).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    #[test]
    fn entries_are_read_in_order_and_bounded() {
        let z = zip_of(&["job.json", "masks/00000.png", "masks/00001.png"]);
        let open = |l: &Limits| read_zip(Path::new("a.zip"), z.clone(), l);
        let a = open(&Limits::default()).unwrap();
        assert_eq!(
            a.names(),
            ["job.json", "masks/00000.png", "masks/00001.png"]
        );
        assert_eq!(a.get("job.json").unwrap(), Some(&b"job.json"[..]));
        assert_eq!(a.get("nothing").unwrap(), None);
        assert_eq!(a.read("masks/00001.png").unwrap(), b"masks/00001.png");
        let files = a.into_source("masks/");
        assert_eq!(&*files.read("00000.png").unwrap(), b"masks/00000.png");
        assert_eq!(files.shown("00000.png"), Path::new("a.zip/masks/00000.png"));
        let files = open(&Limits::default()).unwrap().into_source("");
        assert_eq!(
            &*files.read("masks//00001.png").unwrap(),
            b"masks/00001.png"
        );
        let e = files.read("../job.json").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        let few = Limits {
            max_entries: 2,
            ..Limits::default()
        };
        let e = open(&few).unwrap_err().to_string();
        assert_eq!(e, "a.zip: 3 entries, more than the 2 this reader accepts");
        let small = Limits {
            max_total_bytes: 20,
            ..Limits::default()
        };
        let e = open(&small).unwrap_err().to_string();
        assert!(
            e.starts_with("a.zip: entry \"masks/00000.png\": the entries so far declare 23 bytes"),
            "{e}"
        );
    }

    #[test]
    fn an_entry_is_inflated_only_when_read_and_checked_then() {
        // An entry whose header declares fewer bytes than it holds, and one whose CRC is
        // wrong: the archive opens, and each is refused when read.
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        let stored = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored);
        for n in ["a.txt", "bad-crc.txt", "ok.txt"] {
            w.start_file(n, stored).unwrap();
            w.write_all(n.as_bytes()).unwrap();
        }
        let mut z = w.finish().unwrap().into_inner();
        let at = |z: &[u8], what: &[u8], k: usize| {
            let mut hits = z
                .windows(what.len())
                .enumerate()
                .filter(|(_, w)| *w == what);
            hits.nth(k).unwrap().0
        };
        // The local and central sizes of a.txt: 5 bytes declared as 4.
        for header in [at(&z, b"PK\x03\x04", 0), at(&z, b"PK\x01\x02", 0)] {
            let size = header + if z[header + 2] == 3 { 22 } else { 24 };
            z[size] = 4;
        }
        // bad-crc.txt's data (its name, then its bytes, then its name again).
        let data = at(&z, b"bad-crc.txt", 1);
        z[data] ^= 1;
        let a = read_zip(Path::new("a.zip"), z, &Limits::default()).unwrap();
        let e = a.get("a.txt").unwrap_err().to_string();
        let more = "does not inflate: File is larger than its declared uncompressed size";
        assert_eq!(e, format!("a.zip: entry \"a.txt\": {more}"));
        let e = a.read("bad-crc.txt").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidData);
        assert!(e.to_string().contains("does not inflate"), "{e}");
        assert_eq!(a.read("ok.txt").unwrap(), b"ok.txt");
    }

    #[test]
    fn names_must_stay_inside() {
        for (bad, why) in [
            ("../x", "`..`"),
            ("a/./b", "`.`"),
            ("/x", "absolute"),
            ("a\\b", "backslash"),
            ("a//b", "empty component"),
            ("C:/x", "drive letter"),
            ("", "empty name"),
        ] {
            let e = check_name(bad).unwrap_err();
            assert!(e.contains(why), "{bad}: {e}");
        }
        assert!(check_name("masks/").is_ok());
        assert!(check_name("slices/0001.png").is_ok());
    }
}
