//! What `dmdsl slice` does to the output path: it replaces only a bundle it wrote (nothing
//! a user put there), and a stopped or killed run leaves the old bundle or the new one,
//! never a mix, and no staging directory for long.

use crate::common::*;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Slices the small cube into `out` (in `dir`), quickly; returns the run.
fn slice_cube(dir: &Path, out: &str) -> std::process::Output {
    let f = fixture("cube10.stl");
    run_in(
        dir,
        &[
            "slice",
            f.to_str().unwrap(),
            "-q",
            "-o",
            out,
            "--layer-height",
            "2",
        ],
    )
}

/// Starts a slice of the bunny into `out` that takes long enough to be signalled, and
/// returns once it writes masks into its staging directory.
fn start_long_slice(dir: &Path, out: &str) -> Child {
    let f = fixture("bunny00.stl");
    let child = Command::new(bin())
        .args([
            "slice",
            f.to_str().unwrap(),
            "--layer-height",
            "0.002",
            "-o",
            out,
        ])
        .current_dir(dir)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let prefix = format!(".{out}.tmp-{}", child.id());
    let t = Instant::now();
    while !dir.join(&prefix).join("masks").is_dir() {
        assert!(t.elapsed().as_secs() < 60, "no staging directory appeared");
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

#[test]
fn sigterm_and_sighup_stop_a_slice_like_ctrl_c_and_keep_the_old_bundle() {
    let dir = tempdir("replace-term");
    let o = slice_cube(&dir, "x.dmdjob");
    assert!(o.status.success(), "{}", stderr(&o));
    let before = tree(&dir.join("x.dmdjob"));
    for sig in ["TERM", "HUP"] {
        let child = start_long_slice(&dir, "x.dmdjob");
        signal(&child, sig);
        let out = child.wait_with_output().unwrap();
        assert_eq!(out.status.code(), Some(130), "SIG{sig}: {}", stderr(&out));
        assert_eq!(
            stderr(&out),
            "dmdsl: error: interrupted; nothing was written\n",
            "SIG{sig}"
        );
        assert_eq!(names(&dir), ["x.dmdjob"], "SIG{sig}");
        assert!(tree(&dir.join("x.dmdjob")) == before, "SIG{sig}");
    }
}

#[test]
fn a_killed_slice_leaves_a_staging_dir_that_the_next_run_removes() {
    let dir = tempdir("replace-kill");
    let mut child = start_long_slice(&dir, "x.dmdjob");
    let staging = format!(".x.dmdjob.tmp-{}", child.id());
    child.kill().unwrap(); // SIGKILL: nothing can clean up
    child.wait().unwrap();
    assert_eq!(names(&dir), [staging.as_str()]);
    let o = slice_cube(&dir, "x.dmdjob");
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(names(&dir), ["x.dmdjob"]);
}

#[test]
fn a_file_put_inside_a_bundle_is_never_deleted() {
    let dir = tempdir("replace-notes");
    assert!(slice_cube(&dir, "x.dmdjob").status.success());
    std::fs::write(dir.join("x.dmdjob/notes.txt"), "keep me").unwrap();
    let before = tree(&dir.join("x.dmdjob"));
    let o = slice_cube(&dir, "x.dmdjob");
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(
        stderr(&o),
        "dmdsl: error: x.dmdjob: holds notes.txt, which is not part of a dmdsl bundle; refusing to replace it\n"
    );
    assert!(tree(&dir.join("x.dmdjob")) == before);
    assert_eq!(names(&dir), ["x.dmdjob"]);
    // Once the note is moved out, the bundle is replaced as usual.
    std::fs::remove_file(dir.join("x.dmdjob/notes.txt")).unwrap();
    let o = slice_cube(&dir, "x.dmdjob");
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn a_directory_that_only_looks_like_a_bundle_is_refused() {
    let dir = tempdir("replace-fake");
    let fake = dir.join("thesis.dmdjob");
    std::fs::create_dir(&fake).unwrap();
    std::fs::write(fake.join("job.json"), r#"{"format":"dmdsl-job"}"#).unwrap();
    std::fs::write(fake.join("thesis.tex"), "years of work").unwrap();
    let o = slice_cube(&dir, "thesis.dmdjob");
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(
        stderr(&o),
        "dmdsl: error: thesis.dmdjob: holds thesis.tex, which is not part of a dmdsl bundle; refusing to replace it\n"
    );
    assert_eq!(
        std::fs::read_to_string(fake.join("thesis.tex")).unwrap(),
        "years of work"
    );
    assert_eq!(names(&dir), ["thesis.dmdjob"]);
}

#[cfg(unix)]
#[test]
fn a_symlink_output_is_refused_and_its_target_left_alone() {
    let dir = tempdir("replace-link");
    assert!(slice_cube(&dir, "real.dmdjob").status.success());
    let before = tree(&dir.join("real.dmdjob"));
    std::os::unix::fs::symlink("real.dmdjob", dir.join("link.dmdjob")).unwrap();
    let o = slice_cube(&dir, "link.dmdjob");
    assert_eq!(o.status.code(), Some(2));
    assert_eq!(
        stderr(&o),
        "dmdsl: error: link.dmdjob: is a symbolic link (to real.dmdjob); refusing to replace it (to replace the bundle it points to, give that path as the output)\n"
    );
    let link = std::fs::symlink_metadata(dir.join("link.dmdjob")).unwrap();
    assert!(link.file_type().is_symlink());
    assert!(tree(&dir.join("real.dmdjob")) == before);
    assert_eq!(names(&dir), ["link.dmdjob", "real.dmdjob"]);
}

#[test]
fn slice_help_says_which_signals_stop_it() {
    let o = run_in(&root(), &["slice", "--help"]);
    assert!(o.status.success());
    assert!(
        stdout(&o).contains("130  interrupted (Ctrl-C, SIGTERM or SIGHUP)"),
        "{}",
        stdout(&o)
    );
}
