//! Reading a zip archive from elsewhere, safely: every entry into memory, nothing
//! extracted to the disk.
//!
//! An archive is input like any other file, so it is read as if hostile. Refused, each
//! with one line naming the archive and the entry ([`Error::Archive`]): a file that is
//! not a zip or is truncated or corrupt (a bad CRC included); more than
//! [`Limits::max_entries`] entries; an entry name that is not UTF-8, holds a backslash,
//! a NUL or a drive letter, is absolute, or has an empty, `.` or `..` component; two
//! entries with the same name; an encrypted entry; a method other than stored or
//! deflated; a symbolic link; an entry whose declared size, or the sum of the declared
//! sizes, passes [`Limits::max_entry_bytes`] / [`Limits::max_total_bytes`] (checked before
//! anything is inflated). The declared sizes are not trusted: each entry is inflated
//! through a reader that stops one byte past its declared size, and an entry that does
//! not inflate to exactly that size is refused. Directory entries are checked and then
//! left out.

use crate::error::{Error, Result};
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

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

/// The files of an archive, in memory.
#[derive(Debug, Clone, Default)]
pub struct Archive {
    /// The archive's path, for messages.
    path: PathBuf,
    /// File names in archive order (directories left out).
    names: Vec<String>,
    /// Contents by name.
    files: HashMap<String, Vec<u8>>,
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

    /// The contents of file `name`, if the archive holds it.
    pub fn get(&self, name: &str) -> Option<&[u8]> {
        self.files.get(name).map(Vec::as_slice)
    }

    /// Takes the contents of every file, by name.
    pub fn into_files(self) -> HashMap<String, Vec<u8>> {
        self.files
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

/// True when `bytes` start like a zip archive (a local file header, or the end record of
/// an empty archive).
pub fn looks_like_zip(bytes: &[u8]) -> bool {
    bytes.starts_with(b"PK\x03\x04") || bytes.starts_with(b"PK\x05\x06")
}

/// Reads the archive whose bytes are `bytes` (`path` names it in messages).
pub fn read_zip_bytes(path: &Path, bytes: &[u8], limits: &Limits) -> Result<Archive> {
    let mut archive = Archive {
        path: path.into(),
        ..Archive::default()
    };
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| archive.error(None, format!("not a readable zip archive: {e}")))?;
    if zip.len() > limits.max_entries {
        let msg = format!(
            "{} entries, more than the {} this reader accepts",
            zip.len(),
            limits.max_entries
        );
        return Err(archive.error(None, msg));
    }
    // The zip crate keeps one entry per name: a name listed twice shows in the central
    // directory itself.
    if let Some(dup) = duplicate_name(bytes, zip.len()) {
        return Err(archive.error(Some(&dup), "the name appears twice in the archive"));
    }
    // Inflate each file, never past its declared size.
    for (i, name, size) in declared(&archive, &mut zip, limits)? {
        let at = Some(name.as_str());
        let f = zip
            .by_index(i)
            .map_err(|e| archive.error(at, format!("cannot be read: {e}")))?;
        // Grows as it is read: the declared size is not trusted for the allocation either.
        let mut data = Vec::with_capacity(size.min(1 << 20) as usize);
        // Reading to the end (one byte past the declared size at most) also checks the CRC.
        f.take(size + 1)
            .read_to_end(&mut data)
            .map_err(|e| archive.error(at, format!("does not inflate: {e}")))?;
        if data.len() as u64 != size {
            let got = match data.len() as u64 > size {
                true => format!("more than {size}"),
                false => data.len().to_string(),
            };
            let msg = format!("inflates to {got} bytes, its header declares {size}");
            return Err(archive.error(at, msg));
        }
        archive.names.push(name.clone());
        archive.files.insert(name, data);
    }
    Ok(archive)
}

/// The files of `zip` (`archive` names it in errors) as (index, name, declared size), read
/// from the central directory and checked (names, kinds, methods, declared sizes within
/// `limits`) before anything is inflated.
fn declared(
    archive: &Archive,
    zip: &mut zip::ZipArchive<std::io::Cursor<&[u8]>>,
    limits: &Limits,
) -> Result<Vec<(usize, String, u64)>> {
    let mut entries = Vec::with_capacity(zip.len());
    let mut seen = HashMap::with_capacity(zip.len());
    let mut total: u64 = 0;
    for i in 0..zip.len() {
        let f = zip
            .by_index_raw(i)
            .map_err(|e| archive.error(None, format!("entry {i} cannot be read: {e}")))?;
        let Ok(name) = std::str::from_utf8(f.name_raw()).map(str::to_string) else {
            let shown = String::from_utf8_lossy(f.name_raw()).into_owned();
            return Err(archive.error(Some(&shown), "name is not UTF-8"));
        };
        let bad = |msg: String| archive.error(Some(&name), msg);
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
        let a = read_zip_bytes(Path::new("a.zip"), &z, &Limits::default()).unwrap();
        assert_eq!(
            a.names(),
            ["job.json", "masks/00000.png", "masks/00001.png"]
        );
        assert_eq!(a.get("masks/00001.png"), Some(&b"masks/00001.png"[..]));
        let few = Limits {
            max_entries: 2,
            ..Limits::default()
        };
        let e = read_zip_bytes(Path::new("a.zip"), &z, &few)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "a.zip: 3 entries, more than the 2 this reader accepts");
        let small = Limits {
            max_total_bytes: 20,
            ..Limits::default()
        };
        let e = read_zip_bytes(Path::new("a.zip"), &z, &small)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("a.zip: entry \"masks/00000.png\": the entries so far declare 23 bytes"),
            "{e}"
        );
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
