//! Writing a bundle: atomically (a staging directory swapped into place), replacing only a
//! bundle that holds nothing but its own files, and cleaning up after runs that were killed.

use super::{Manifest, FORMAT, MANIFEST};
use crate::error::{Error, Result};
use std::collections::BTreeSet;
use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};

/// True if `dir` looks like a dmdsl bundle (has a `job.json` whose format is ours). Whether
/// a bundle may be replaced is a stricter question: see [`BundleWriter`].
pub fn is_bundle(dir: &Path) -> bool {
    manifest_json(dir).is_some()
}

/// `job.json` of `dir` as JSON, if it is a dmdsl manifest (`format` is [`FORMAT`]).
fn manifest_json(dir: &Path) -> Option<serde_json::Value> {
    let text = std::fs::read(dir.join(MANIFEST)).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&text).ok()?;
    (v.get("format")?.as_str()? == FORMAT).then_some(v)
}

/// The files of the bundle a manifest describes, as paths relative to the bundle with `/`:
/// `job.json`, every layer's masks and the gray maps of `optics` and `projector_optics`.
/// Read from the JSON loosely, so a manifest of any version this build reads qualifies.
fn bundle_files(v: &serde_json::Value) -> BTreeSet<String> {
    use serde_json::Value;
    fn list<'a>(v: &'a Value, key: &str) -> &'a [Value] {
        v.get(key)
            .and_then(Value::as_array)
            .map_or(&[], Vec::as_slice)
    }
    let text = |v: &Value, key: &str| v.get(key).and_then(Value::as_str).map(String::from);
    let mut files = BTreeSet::from([MANIFEST.to_string()]);
    for layer in list(v, "layers") {
        files.extend(list(layer, "masks").iter().filter_map(|m| text(m, "file")));
    }
    files.extend(v.get("optics").and_then(|o| text(o, "gray_map")));
    files.extend(
        list(v, "projector_optics")
            .iter()
            .filter_map(|o| text(o, "gray_map")),
    );
    files
}

/// The first entry under the bundle directory `dir` (in name order, depth first) that is not
/// part of the bundle its manifest `v` describes, as a relative path (a directory with a
/// trailing `/`); `None` if every entry is part of it. Bundle files are regular files that
/// the manifest names; bundle directories are `masks` and the directories of those files.
/// Anything else, symbolic links included, is foreign.
fn first_foreign(dir: &Path, v: &serde_json::Value) -> Result<Option<String>> {
    let files = bundle_files(v);
    let mut dirs = BTreeSet::from(["masks".to_string()]);
    for f in &files {
        let mut p = f.as_str();
        while let Some(k) = p.rfind('/') {
            p = &p[..k];
            dirs.insert(p.to_string());
        }
    }
    foreign_in(dir, "", &files, &dirs)
}

/// [`first_foreign`] in `dir`, the bundle's directory `prefix` (empty or ending in `/`).
fn foreign_in(
    dir: &Path,
    prefix: &str,
    files: &BTreeSet<String>,
    dirs: &BTreeSet<String>,
) -> Result<Option<String>> {
    let mut entries = Vec::new();
    for e in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let e = e.map_err(|e| Error::io(dir, e))?;
        let kind = e.file_type().map_err(|err| Error::io(e.path(), err))?;
        entries.push((e.file_name(), kind));
    }
    entries.sort_by(|a, b| a.0.cmp(&b.0));
    for (name, kind) in entries {
        let rel = format!("{prefix}{}", name.to_string_lossy());
        let exact = name.to_str().is_some();
        if exact && kind.is_file() && files.contains(&rel) {
            continue;
        }
        if exact && kind.is_dir() && dirs.contains(&rel) {
            match foreign_in(&dir.join(&name), &format!("{rel}/"), files, dirs)? {
                Some(f) => return Ok(Some(f)),
                None => continue,
            }
        }
        return Ok(Some(if kind.is_dir() { rel + "/" } else { rel }));
    }
    Ok(None)
}

/// Whether a bundle may be written at `dest`: `Ok(false)` when nothing is there, `Ok(true)`
/// when a dmdsl bundle that holds nothing but its own files is there (it will be replaced),
/// and an error naming what is in the way otherwise.
fn check_replaceable(dest: &Path) -> Result<bool> {
    let refuse = |msg: String| Error::Bundle {
        path: dest.into(),
        msg,
    };
    let meta = match std::fs::symlink_metadata(dest) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(Error::io(dest, e)),
        Ok(m) => m,
    };
    crate::output::refuse_special(dest)?;
    let manifest = if meta.is_dir() {
        manifest_json(dest)
    } else {
        None
    };
    let Some(v) = manifest else {
        return Err(refuse(
            "exists and is not a dmdsl bundle; refusing to replace it".into(),
        ));
    };
    if let Some(f) = first_foreign(dest, &v)? {
        return Err(refuse(format!(
            "holds {f}, which is not part of a dmdsl bundle; refusing to replace it"
        )));
    }
    Ok(true)
}

/// Name of the staging directory of process `pid` for the bundle named `name`:
/// `.NAME.tmp-PID`.
fn staging_name(name: &OsStr, pid: u32) -> OsString {
    let mut s = OsString::from(".");
    s.push(name);
    s.push(format!(".tmp-{pid}"));
    s
}

/// If `entry` is exactly `.NAME.tmp-PID` or `.NAME.tmp-PID.old` for the bundle named `name`
/// (PID in decimal as a process writes it), the PID and whether it is the `.old` form.
fn staging_pid(entry: &OsStr, name: &OsStr) -> Option<(u32, bool)> {
    let rest = entry
        .as_encoded_bytes()
        .strip_prefix(b".")?
        .strip_prefix(name.as_encoded_bytes())?
        .strip_prefix(b".tmp-")?;
    let (digits, old) = match rest.strip_suffix(b".old") {
        Some(d) => (d, true),
        None => (rest, false),
    };
    let pid: u32 = std::str::from_utf8(digits).ok()?.parse().ok()?;
    (pid.to_string().as_bytes() == digits).then_some((pid, old))
}

/// True if nothing (not even a dangling symbolic link) is at `p`.
fn absent(p: &Path) -> bool {
    matches!(std::fs::symlink_metadata(p), Err(e) if e.kind() == std::io::ErrorKind::NotFound)
}

/// What killed runs (SIGKILL, an abort, a power cut) left beside `dest` while writing it:
/// the entries `.NAME.tmp-PID` and `.NAME.tmp-PID.old` whose process no longer runs, each
/// with whether it is the `.old` form and its type. Only names of exactly that form count.
/// Linux only (a process runs if `/proc/PID` exists); elsewhere none.
pub(crate) fn stale_siblings(dest: &Path) -> Vec<(PathBuf, bool, std::fs::FileType)> {
    let (Some(running), Some(name)) = (process_runs(), dest.file_name()) else {
        return Vec::new();
    };
    let parent = match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Vec::new();
    };
    entries
        .flatten()
        .filter_map(|e| {
            let (pid, old) = staging_pid(&e.file_name(), name)?;
            let dead = pid != std::process::id() && !running(pid);
            let kind = e.file_type().ok()?;
            dead.then(|| (e.path(), old, kind))
        })
        .collect()
}

/// Cleans up after runs that were killed while writing the bundle `dest`: their staging
/// directories ([`stale_siblings`]). First, if `dest` is missing and such an `.old` exists
/// (the run died between moving the old bundle aside and moving the new one in), the
/// `.old` is renamed back to `dest`. Best effort: what cannot be removed stays.
fn clean_stale(dest: &Path) {
    let (mut staging, mut old) = (Vec::new(), Vec::new());
    for (p, is_old, kind) in stale_siblings(dest) {
        match (kind.is_dir(), is_old) {
            (true, true) => old.push(p),
            (true, false) => staging.push(p),
            _ => {}
        }
    }
    old.sort();
    if absent(dest) && !old.is_empty() && std::fs::rename(&old[0], dest).is_ok() {
        old.remove(0);
    }
    for p in staging {
        let _ = std::fs::remove_dir_all(p);
    }
    // An `.old` is removed only once a bundle is at `dest` again.
    if !absent(dest) {
        for p in old {
            let _ = std::fs::remove_dir_all(p);
        }
    }
}

/// A test whether process `pid` runs, where the system offers a reliable one: on Linux
/// `/proc/PID` exists (and `/proc` is mounted).
#[cfg(target_os = "linux")]
fn process_runs() -> Option<fn(u32) -> bool> {
    Path::new("/proc/self")
        .exists()
        .then_some(|pid| Path::new("/proc").join(pid.to_string()).exists())
}

/// A test whether a process runs: none here, so stale staging directories are left alone.
#[cfg(not(target_os = "linux"))]
fn process_runs() -> Option<fn(u32) -> bool> {
    None
}

/// `renameat2(from, to, flags)`: `Ok(false)` where the kernel or the filesystem does not
/// support the call or its flags (the caller then falls back to `rename`).
#[cfg(target_os = "linux")]
fn renameat2(from: &Path, to: &Path, flags: libc::c_uint) -> std::io::Result<bool> {
    use std::os::unix::ffi::OsStrExt;
    let from = std::ffi::CString::new(from.as_os_str().as_bytes())?;
    let to = std::ffi::CString::new(to.as_os_str().as_bytes())?;
    // SAFETY: both paths are NUL-terminated strings that outlive the call, which only reads
    // them; the other arguments are plain integers.
    let rc = unsafe {
        libc::syscall(
            libc::SYS_renameat2,
            libc::AT_FDCWD,
            from.as_ptr(),
            libc::AT_FDCWD,
            to.as_ptr(),
            flags,
        )
    };
    if rc == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    match e.raw_os_error() {
        // ENOSYS: no renameat2 (old kernel); EINVAL: the filesystem does not support the
        // flag; EPERM: some container sandboxes refuse unknown system calls so (a real
        // permission problem makes the fallback's rename fail the same way).
        Some(libc::ENOSYS | libc::EINVAL | libc::EPERM) => Ok(false),
        _ => Err(e),
    }
}

/// Swaps the directories `a` and `b` in one step; `Ok(false)` where that is not supported.
fn exchange(a: &Path, b: &Path) -> std::io::Result<bool> {
    #[cfg(target_os = "linux")]
    return renameat2(a, b, libc::RENAME_EXCHANGE);
    #[cfg(not(target_os = "linux"))]
    return {
        let _ = (a, b);
        Ok(false)
    };
}

/// Renames `from` to `to` unless something is at `to` (error `AlreadyExists`); `Ok(false)`
/// where that is not supported.
fn rename_noreplace(from: &Path, to: &Path) -> std::io::Result<bool> {
    #[cfg(target_os = "linux")]
    return renameat2(from, to, libc::RENAME_NOREPLACE);
    #[cfg(not(target_os = "linux"))]
    return {
        let _ = (from, to);
        Ok(false)
    };
}

/// Replaces the bundle `dest` by `staging` with two renames, where they cannot be swapped
/// in one step: `dest` → `old`, `staging` → `dest`, then `old` is removed. A run killed
/// between the two renames leaves `old` and no `dest`; the next run renames `old` back
/// ([`BundleWriter::create`]).
fn replace_by_renames(staging: &Path, dest: &Path, old: &Path) -> Result<()> {
    std::fs::rename(dest, old).map_err(|e| Error::io(dest, e))?;
    if let Err(e) = std::fs::rename(staging, dest) {
        let _ = std::fs::rename(old, dest);
        return Err(Error::io(dest, e));
    }
    let _ = std::fs::remove_dir_all(old);
    Ok(())
}

/// Writes a bundle atomically.
///
/// Files go into a hidden staging directory `.NAME.tmp-PID` beside the destination `NAME`;
/// [`BundleWriter::finish`] writes the manifest last and moves the staging directory into
/// place. Dropping the writer without finishing removes the staging directory.
///
/// Replacement: an existing destination is replaced only if dmdsl wrote everything in it,
/// that is, it is a directory with a dmdsl `job.json` and every other entry is a file the
/// manifest names (masks, gray maps) or a directory holding only such files. Anything else
/// (a file or a foreign directory at the path, a `notes.txt` put inside a bundle, a symbolic
/// link, even one to a bundle) is refused with an error naming the first foreign entry;
/// the check is made when the writer is created and again just before the replacement.
/// On Linux the new bundle and the old one are swapped in one step (`renameat2` with
/// `RENAME_EXCHANGE`), so the path holds the old bundle or the new one at every instant;
/// where that is not supported, two renames are used and a run killed between them is
/// repaired by the next one. Staging directories of killed runs are removed by the next
/// run writing the same bundle (Linux).
#[derive(Debug)]
pub struct BundleWriter {
    dest: PathBuf,
    staging: PathBuf,
    done: bool,
}

impl BundleWriter {
    /// Prepares to write a bundle at `dest`: cleans up after killed runs for the same
    /// destination (see [`BundleWriter`]) and creates the staging directory. Fails if
    /// `dest` exists and may not be replaced.
    pub fn create(dest: &Path) -> Result<BundleWriter> {
        let name = dest.file_name().ok_or_else(|| Error::Bundle {
            path: dest.into(),
            msg: "output path has no file name".into(),
        })?;
        let parent = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        if let Some(msg) = crate::output::parent_problem(dest) {
            return Err(Error::Bundle {
                path: dest.into(),
                msg,
            });
        }
        clean_stale(dest);
        check_replaceable(dest)?;
        let staging = parent.join(staging_name(name, std::process::id()));
        if staging.exists() {
            let _ = std::fs::remove_dir_all(&staging);
        }
        // Errors name the bundle: the staging directory is ours, not the user's.
        std::fs::create_dir(&staging).map_err(|e| Error::io(dest, e))?;
        let w = BundleWriter {
            dest: dest.to_path_buf(),
            staging,
            done: false,
        };
        w.create_dir("masks")?;
        Ok(w)
    }

    /// The staging directory (where files are written until [`finish`](Self::finish)).
    pub fn staging_dir(&self) -> &Path {
        &self.staging
    }

    /// Creates a subdirectory (relative path) in the staging directory. An error names it
    /// in the bundle (`part.dmdjob/masks`), not in the staging directory.
    pub fn create_dir(&self, rel: &str) -> Result<()> {
        let p = self.staging.join(rel);
        std::fs::create_dir_all(&p).map_err(|e| Error::io(self.dest.join(rel), e))
    }

    /// Writes a file (relative path) into the staging directory. An error names it in the
    /// bundle (`part.dmdjob/masks/00012.png`), not in the staging directory.
    pub fn write_file(&self, rel: &str, bytes: &[u8]) -> Result<()> {
        let p = self.staging.join(rel);
        std::fs::write(&p, bytes).map_err(|e| Error::io(self.dest.join(rel), e))
    }

    /// Writes the manifest and moves the bundle into place, replacing an older bundle (if
    /// it may still be replaced: see [`BundleWriter`]).
    pub fn finish(self, manifest: &Manifest) -> Result<PathBuf> {
        self.commit(&manifest.to_json())
    }

    /// Writes `json` as the manifest and moves the bundle into place.
    fn commit(mut self, json: &[u8]) -> Result<PathBuf> {
        self.write_file(MANIFEST, json)?;
        let dest = self.dest.clone();
        if check_replaceable(&dest)? {
            if exchange(&self.staging, &dest).map_err(|e| Error::io(&dest, e))? {
                // The old bundle is now at the staging name.
                self.done = true;
                let _ = std::fs::remove_dir_all(&self.staging);
            } else {
                let mut old = self.staging.clone().into_os_string();
                old.push(".old");
                replace_by_renames(&self.staging, &dest, Path::new(&old))?;
                self.done = true;
            }
        } else {
            match rename_noreplace(&self.staging, &dest) {
                Ok(true) => {}
                Ok(false) => {
                    std::fs::rename(&self.staging, &dest).map_err(|e| Error::io(&dest, e))?
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    return Err(Error::Bundle {
                        path: dest,
                        msg: "appeared while the bundle was being written; refusing to replace it"
                            .into(),
                    })
                }
                Err(e) => return Err(Error::io(&dest, e)),
            }
            self.done = true;
        }
        Ok(dest)
    }
}

impl Drop for BundleWriter {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writer_refuses_foreign_dir_and_cleans_up() {
        let tmp = std::env::temp_dir().join(format!("dmdsl-bw-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir_all(tmp.join("foreign")).unwrap();
        assert!(BundleWriter::create(&tmp.join("foreign")).is_err());
        {
            let w = BundleWriter::create(&tmp.join("a.dmdjob")).unwrap();
            w.write_file("masks/x.png", b"123").unwrap();
            // dropped without finish
        }
        let names: Vec<_> = std::fs::read_dir(&tmp)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("foreign")]);
        let _ = std::fs::remove_dir_all(&tmp);
    }

    fn scratch(tag: &str) -> PathBuf {
        crate::test_support::scratch("bw", tag)
    }

    use crate::test_support::names;

    /// The PID of a process that has ended.
    fn dead_pid() -> u32 {
        let mut c = std::process::Command::new("true").spawn().unwrap();
        let pid = c.id();
        c.wait().unwrap();
        pid
    }

    /// A manifest naming the masks `masks`.
    fn manifest_of(masks: &[&str]) -> String {
        let layers: Vec<String> = masks
            .iter()
            .map(|m| format!(r#"{{"masks": [{{"file": "{m}"}}]}}"#))
            .collect();
        format!(
            r#"{{"format": "dmdsl-job", "version": 2, "layers": [{}]}}"#,
            layers.join(", ")
        )
    }

    /// Writes a bundle at `dir` by hand: the masks, each holding `tag`, and their manifest.
    fn put_bundle(dir: &Path, masks: &[&str], tag: &str) {
        std::fs::create_dir_all(dir.join("masks")).unwrap();
        for m in masks {
            std::fs::write(dir.join(m), tag).unwrap();
        }
        std::fs::write(dir.join(MANIFEST), manifest_of(masks)).unwrap();
    }

    /// Writes a bundle at `dest` through a writer: the masks, each holding `tag`.
    fn write_bundle(dest: &Path, masks: &[&str], tag: &str) -> Result<PathBuf> {
        let w = BundleWriter::create(dest)?;
        for m in masks {
            w.write_file(m, tag.as_bytes())?;
        }
        w.commit(manifest_of(masks).as_bytes())
    }

    #[test]
    fn staging_names_match_exactly() {
        let name = OsStr::new("x.dmdjob");
        let pid = |s: &str| staging_pid(OsStr::new(s), name);
        assert_eq!(pid(".x.dmdjob.tmp-123"), Some((123, false)));
        assert_eq!(pid(".x.dmdjob.tmp-123.old"), Some((123, true)));
        for other in [
            "x.dmdjob.tmp-123",
            ".x.dmdjob.tmp-",
            ".x.dmdjob.tmp-0123",
            ".x.dmdjob.tmp-+123",
            ".x.dmdjob.tmp-123.bak",
            ".x.dmdjob.tmp-123.old.old",
            ".x.dmdjob.tmp-12a",
            ".x.dmdjob.tmp-99999999999",
            ".y.dmdjob.tmp-123",
            ".x.dmdjobs.tmp-123",
            ".x.dmdjob.tmp-123 ",
        ] {
            assert_eq!(pid(other), None, "{other}");
        }
        assert_eq!(staging_name(name, 42), OsString::from(".x.dmdjob.tmp-42"));
    }

    #[test]
    fn replacing_swaps_the_old_bundle_for_the_new_and_leaves_nothing_else() {
        let tmp = scratch("swap");
        let dest = tmp.join("x.dmdjob");
        write_bundle(&dest, &["masks/00000.png", "masks/00001.png"], "old").unwrap();
        write_bundle(&dest, &["masks/00000.png"], "new").unwrap();
        assert_eq!(names(&tmp), ["x.dmdjob"]);
        assert_eq!(names(&dest.join("masks")), ["00000.png"]);
        assert_eq!(
            std::fs::read_to_string(dest.join("masks/00000.png")).unwrap(),
            "new"
        );
        let _ = std::fs::remove_dir_all(&tmp);
    }

    #[test]
    fn exchange_swaps_two_directories_or_leaves_both() {
        let tmp = scratch("exchange");
        let (a, b) = (tmp.join("a"), tmp.join("b"));
        put_bundle(&a, &["masks/00000.png"], "a");
        put_bundle(&b, &["masks/00000.png"], "b");
        let swapped = exchange(&a, &b).unwrap();
        let read = |d: &Path| std::fs::read_to_string(d.join("masks/00000.png")).unwrap();
        if swapped {
            assert_eq!((read(&a), read(&b)), ("b".into(), "a".into()));
        } else {
            // Not supported here: nothing moved (the writer then uses two renames).
            assert_eq!((read(&a), read(&b)), ("a".into(), "b".into()));
        }
        let _ = std::fs::remove_dir_all(&tmp);
    }

    #[test]
    fn replacing_by_two_renames_leaves_the_new_bundle_only() {
        // The fallback where directories cannot be swapped in one step.
        let tmp = scratch("renames");
        let dest = tmp.join("x.dmdjob");
        let staging = tmp.join(".x.dmdjob.tmp-7");
        put_bundle(&dest, &["masks/00000.png", "masks/00001.png"], "old");
        put_bundle(&staging, &["masks/00000.png"], "new");
        replace_by_renames(&staging, &dest, &tmp.join(".x.dmdjob.tmp-7.old")).unwrap();
        assert_eq!(names(&tmp), ["x.dmdjob"]);
        assert_eq!(names(&dest.join("masks")), ["00000.png"]);
        assert_eq!(
            std::fs::read_to_string(dest.join("masks/00000.png")).unwrap(),
            "new"
        );
        let _ = std::fs::remove_dir_all(&tmp);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn staging_dirs_of_dead_processes_are_removed_and_nothing_else() {
        let tmp = scratch("stale");
        let dead = dead_pid();
        let dest = tmp.join("x.dmdjob");
        put_bundle(&dest, &["masks/00000.png"], "old");
        let gone = [
            format!(".x.dmdjob.tmp-{dead}"),
            format!(".x.dmdjob.tmp-{dead}.old"),
        ];
        let kept = [
            // PID 1 always runs.
            ".x.dmdjob.tmp-1".to_string(),
            format!(".x.dmdjob.tmp-0{dead}"),
            format!(".x.dmdjob.tmp-{dead}.bak"),
            format!(".y.dmdjob.tmp-{dead}"),
            format!("x.dmdjob.tmp-{dead}"),
        ];
        for d in gone.iter().chain(&kept) {
            std::fs::create_dir(tmp.join(d)).unwrap();
            std::fs::write(tmp.join(d).join("f.png"), "x").unwrap();
        }
        // A file with a staging name is not a staging directory.
        let file = format!(".x.dmdjob.tmp-{}", dead_pid());
        std::fs::write(tmp.join(&file), "x").unwrap();
        write_bundle(&dest, &["masks/00000.png"], "new").unwrap();
        let mut want: Vec<String> = kept.to_vec();
        want.push(file);
        want.push("x.dmdjob".into());
        want.sort();
        assert_eq!(names(&tmp), want);
        assert_eq!(
            std::fs::read_to_string(dest.join("masks/00000.png")).unwrap(),
            "new"
        );
        let _ = std::fs::remove_dir_all(&tmp);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_old_bundle_of_a_run_killed_between_renames_is_restored() {
        // Killed after `x.dmdjob` → `.old` and before the staging directory → `x.dmdjob`.
        let tmp = scratch("restore");
        let dead = dead_pid();
        let dest = tmp.join("x.dmdjob");
        put_bundle(
            &tmp.join(format!(".x.dmdjob.tmp-{dead}.old")),
            &["masks/00000.png"],
            "old",
        );
        put_bundle(
            &tmp.join(format!(".x.dmdjob.tmp-{dead}")),
            &["masks/00000.png"],
            "new",
        );
        let w = BundleWriter::create(&dest).unwrap();
        assert_eq!(
            std::fs::read_to_string(dest.join("masks/00000.png")).unwrap(),
            "old"
        );
        drop(w);
        assert_eq!(names(&tmp), ["x.dmdjob"]);
        let _ = std::fs::remove_dir_all(&tmp);
    }

    #[test]
    fn only_a_bundle_holding_nothing_foreign_is_replaced() {
        let tmp = scratch("foreign");
        let refused = |dest: &Path| -> String {
            let e = write_bundle(dest, &["masks/00000.png"], "new").unwrap_err();
            assert_eq!(e.exit_code(), 2);
            e.to_string()
        };
        let mask = |d: &Path| std::fs::read_to_string(d.join("masks/00000.png")).unwrap();

        // A note put inside a real bundle.
        let b = tmp.join("notes.dmdjob");
        put_bundle(&b, &["masks/00000.png"], "old");
        std::fs::write(b.join("notes.txt"), "keep").unwrap();
        assert_eq!(
            refused(&b),
            format!(
                "{}: holds notes.txt, which is not part of a dmdsl bundle; refusing to replace it",
                b.display()
            )
        );
        assert_eq!(
            std::fs::read_to_string(b.join("notes.txt")).unwrap(),
            "keep"
        );
        assert_eq!(mask(&b), "old");

        // A directory with a dmdsl-looking job.json and someone's work.
        let f = tmp.join("fake");
        std::fs::create_dir(&f).unwrap();
        std::fs::write(f.join(MANIFEST), r#"{"format":"dmdsl-job"}"#).unwrap();
        std::fs::write(f.join("thesis.tex"), "keep").unwrap();
        assert!(refused(&f).ends_with(
            ": holds thesis.tex, which is not part of a dmdsl bundle; refusing to replace it"
        ));
        assert!(f.join("thesis.tex").exists());

        // A mask the manifest does not list.
        let b = tmp.join("extra-mask.dmdjob");
        put_bundle(&b, &["masks/00000.png"], "old");
        std::fs::write(b.join("masks/00009.png"), "x").unwrap();
        assert!(refused(&b).contains(": holds masks/00009.png, which"));
        assert!(b.join("masks/00009.png").exists());

        // An empty directory.
        let b = tmp.join("extra-dir.dmdjob");
        put_bundle(&b, &["masks/00000.png"], "old");
        std::fs::create_dir(b.join("figures")).unwrap();
        assert!(refused(&b).contains(": holds figures/, which"));
        assert!(b.join("figures").is_dir());

        // A symbolic link where the manifest names a mask.
        #[cfg(unix)]
        {
            let b = tmp.join("extra-link.dmdjob");
            put_bundle(&b, &[], "old");
            std::fs::write(b.join(MANIFEST), manifest_of(&["masks/00000.png"])).unwrap();
            std::os::unix::fs::symlink(tmp.join("elsewhere"), b.join("masks/00000.png")).unwrap();
            assert!(refused(&b).contains(": holds masks/00000.png, which"));
        }

        // A symbolic link to a bundle: neither the link nor its target is replaced.
        #[cfg(unix)]
        {
            let target = tmp.join("target.dmdjob");
            put_bundle(&target, &["masks/00000.png"], "old");
            let link = tmp.join("link.dmdjob");
            std::os::unix::fs::symlink("target.dmdjob", &link).unwrap();
            assert!(refused(&link).contains(": is a symbolic link (to target.dmdjob); refusing"));
            assert!(std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink());
            assert_eq!(mask(&target), "old");
        }

        // A plain file.
        std::fs::write(tmp.join("file.dmdjob"), "keep").unwrap();
        assert!(refused(&tmp.join("file.dmdjob"))
            .ends_with(": exists and is not a dmdsl bundle; refusing to replace it"));

        // A bundle with every kind of file dmdsl writes is replaced.
        let full = tmp.join("full.dmdjob");
        std::fs::create_dir_all(full.join("masks/p0")).unwrap();
        std::fs::create_dir_all(full.join("masks/p1")).unwrap();
        std::fs::create_dir_all(full.join("optics")).unwrap();
        for f in [
            "masks/p0/00000.png",
            "masks/p1/00000.png",
            "optics/a-gray-map.png",
            "optics/b-gray-map.png",
        ] {
            std::fs::write(full.join(f), "old").unwrap();
        }
        std::fs::write(
            full.join(MANIFEST),
            r#"{"format": "dmdsl-job", "version": 2,
                "layers": [{"masks": [{"file": "masks/p0/00000.png"}, {"file": "masks/p1/00000.png"}]}],
                "optics": {"gray_map": "optics/a-gray-map.png"},
                "projector_optics": [{"gray_map": "optics/b-gray-map.png"}]}"#,
        )
        .unwrap();
        write_bundle(&full, &["masks/00000.png"], "new").unwrap();
        assert_eq!(mask(&full), "new");

        // Nothing is left beside the destinations.
        assert!(
            names(&tmp).iter().all(|n| !n.starts_with('.')),
            "{:?}",
            names(&tmp)
        );
        let _ = std::fs::remove_dir_all(&tmp);
    }

    #[test]
    fn finish_checks_the_destination_again() {
        let tmp = scratch("recheck");
        let dest = tmp.join("x.dmdjob");
        let w = BundleWriter::create(&dest).unwrap();
        w.write_file("masks/00000.png", b"new").unwrap();
        // Meanwhile someone puts a directory of their own at the path.
        put_bundle(&dest, &["masks/00000.png"], "old");
        std::fs::write(dest.join("notes.txt"), "keep").unwrap();
        let e = w
            .commit(manifest_of(&["masks/00000.png"]).as_bytes())
            .unwrap_err();
        assert!(e.to_string().contains("holds notes.txt"), "{e}");
        assert_eq!(names(&tmp), ["x.dmdjob"]);
        assert!(dest.join("notes.txt").exists());
        let _ = std::fs::remove_dir_all(&tmp);
    }
}
