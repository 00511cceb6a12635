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
        .stoppable()
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

/// One rule for links, whatever the output (a bundle directory, a one-file job, a trace, a
/// calibration): a symbolic link at the path is refused, what it points to left alone.
#[cfg(unix)]
#[test]
fn a_symlink_output_is_refused_and_its_target_left_alone() {
    let dir = tempdir("replace-link");
    assert!(slice_cube(&dir, "real.dmdjob").status.success());
    assert!(slice_cube(&dir, "real.sl1").status.success());
    std::fs::write(dir.join("real.csv"), "old").unwrap();
    let before = tree(&dir);
    let link = |name: &str, to: &str| std::os::unix::fs::symlink(to, dir.join(name)).unwrap();
    link("link.dmdjob", "real.dmdjob");
    link("link.sl1", "real.sl1");
    link("link.csv", "real.csv");
    let refused = |o: std::process::Output, name: &str, to: &str| {
        assert_eq!(o.status.code(), Some(2), "{name}");
        assert_eq!(
            stderr(&o),
            format!("dmdsl: error: {name}: is a symbolic link (to {to}); refusing to replace it (to replace what it points to, give that path as the output)\n")
        );
    };
    refused(
        slice_cube(&dir, "link.dmdjob"),
        "link.dmdjob",
        "real.dmdjob",
    );
    refused(slice_cube(&dir, "link.sl1"), "link.sl1", "real.sl1");
    let export = ["export", "real.dmdjob", "-o", "link.sl1"];
    refused(run_in(&dir, &export), "link.sl1", "real.sl1");
    let trace = ["run", "real.dmdjob", "--trace", "link.csv"];
    refused(run_in(&dir, &trace), "link.csv", "real.csv");
    let m = fixture("measurements.csv");
    let calibrate = [
        "calibrate",
        m.to_str().unwrap(),
        "-o",
        "link.csv",
        "--no-plots",
    ];
    refused(run_in(&dir, &calibrate), "link.csv", "real.csv");
    for name in ["link.dmdjob", "link.sl1", "link.csv"] {
        assert!(std::fs::symlink_metadata(dir.join(name))
            .unwrap()
            .file_type()
            .is_symlink());
    }
    let after: Vec<_> = tree(&dir)
        .into_iter()
        .filter(|(n, _)| !n.starts_with("link"))
        .collect();
    assert!(after == before);
}

/// A device, a FIFO or a socket at an output path is refused, whatever the output:
/// renaming over it would replace the node itself (as root, `--trace /dev/null` would
/// replace /dev/null with the trace). A FIFO stands in for a device here.
#[cfg(unix)]
#[test]
fn a_special_file_output_is_refused_and_left_alone() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempdir("replace-fifo");
    assert!(slice_cube(&dir, "real.dmdjob").status.success());
    for name in ["pipe.csv", "pipe.sl1", "pipe.png", "pipe.dmdjob"] {
        let made = std::process::Command::new("mkfifo")
            .arg(dir.join(name))
            .status()
            .unwrap();
        assert!(made.success());
    }
    let m = fixture("measurements.csv");
    let m = m.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (&["run", "real.dmdjob", "--trace", "pipe.csv"], "pipe.csv"),
        (&["run", "real.dmdjob", "--plot", "pipe.png"], "pipe.png"),
        (&["export", "real.dmdjob", "-o", "pipe.sl1"], "pipe.sl1"),
        (
            &["calibrate", m, "-o", "pipe.csv", "--no-plots"],
            "pipe.csv",
        ),
        (
            &["inspect", "real.dmdjob", "--chart", "pipe.png"],
            "pipe.png",
        ),
    ];
    for (args, name) in cases {
        let o = run_in(&dir, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert_eq!(
            stderr(&o),
            format!("dmdsl: error: {name}: is a FIFO, not a file; refusing to replace it\n"),
            "{args:?}"
        );
    }
    let o = slice_cube(&dir, "pipe.dmdjob");
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(
        stderr(&o),
        "dmdsl: error: pipe.dmdjob: is a FIFO, not a file; refusing to replace it\n"
    );
    for name in ["pipe.csv", "pipe.sl1", "pipe.png", "pipe.dmdjob"] {
        let t = std::fs::symlink_metadata(dir.join(name))
            .unwrap()
            .file_type();
        assert!(t.is_fifo(), "{name}");
    }
    assert_eq!(
        names(&dir),
        [
            "pipe.csv",
            "pipe.dmdjob",
            "pipe.png",
            "pipe.sl1",
            "real.dmdjob"
        ]
    );
}

/// A write that fails (a full disk: here a file-size limit, `RLIMIT_FSIZE`, which fails
/// writes past it with EFBIG as a full disk does with ENOSPC) is one error line naming the
/// output, exit 2, and leaves nothing: a one-file job (the zip library printed its own
/// line in front), a trace (its temporary file stayed), a calibration, a bundle directory.
#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_is_one_error_line_and_leaves_nothing() {
    let dir = tempdir("replace-full");
    assert!(slice_cube(&dir, "cube.dmdjob").status.success());
    let before = names(&dir);
    let f = fixture("cube10.stl");
    let model = f.to_str().unwrap();
    let err = "File too large (os error 27)";
    let m = fixture("measurements.csv");
    let m = m.to_str().unwrap();
    let cases: [(&[&str], String, u64); 5] = [
        (
            &["calibrate", m, "-o", "c.toml", "--no-plots"],
            format!("c.toml: {err}"),
            200,
        ),
        (
            &["export", "cube.dmdjob", "-o", "a.sl1"],
            format!("a.sl1: {err}"),
            4096,
        ),
        (
            &["slice", model, "-o", "b.dmdjob.zip"],
            format!("b.dmdjob.zip: {err}"),
            4096,
        ),
        (
            &["run", "cube.dmdjob", "--trace", "t.csv"],
            format!("t.csv: {err}"),
            1000,
        ),
        (
            &["slice", model, "-o", "c.dmdjob"],
            "c.dmdjob/masks/00".into(),
            4096,
        ),
    ];
    for (args, says, limit) in cases {
        let (o, code, _) = run_limited(&dir, args, None, Some(limit));
        let e = stderr(&o);
        assert_eq!(code, Some(2), "{args:?}: {e}");
        assert_eq!(e.lines().count(), 1, "{args:?}: {e}");
        assert!(
            e.starts_with(&format!("dmdsl: error: {says}")),
            "{args:?}: {e}"
        );
        assert_eq!(names(&dir), before, "{args:?}");
    }
}

/// Errors name the output, never the hidden temporary file dmdsl writes first
/// (`ro/.a.sl1.tmp-27948: Permission denied`): a one-file output whose folder cannot hold
/// it (here a file in the way, which fails for every user, root included). The bundle
/// directory's files are named in the bundle (above, on a full disk).
#[test]
fn errors_name_the_output_not_its_temporary_file() {
    let dir = tempdir("replace-staging");
    assert!(slice_cube(&dir, "cube.dmdjob").status.success());
    std::fs::write(dir.join("ro"), "a file, not a folder").unwrap();
    for (args, out) in [
        (&["export", "cube.dmdjob", "-o", "ro/a.sl1"][..], "ro/a.sl1"),
        (&["run", "cube.dmdjob", "--trace", "ro/t.csv"], "ro/t.csv"),
    ] {
        let o = run_in(&dir, args);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let e = stderr(&o);
        assert_eq!(e, format!("dmdsl: error: {out}: ro is not a directory\n"));
    }
}

/// A success summary shows control characters of a path as escapes, as errors do.
#[cfg(unix)]
#[test]
fn a_summary_escapes_control_characters_of_a_name() {
    let dir = tempdir("replace-escapes");
    assert!(slice_cube(&dir, "cube.dmdjob").status.success());
    let name = "a\x1b[2Jb.sl1";
    let o = run_in(&dir, &["export", "cube.dmdjob", "-o", name]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).starts_with("a\\u{1b}[2Jb.sl1: sl1 of 5"),
        "{:?}",
        stdout(&o)
    );
    let o = run_in(
        &dir,
        &[
            "slice",
            fixture("cube10.stl").to_str().unwrap(),
            "--layer-height",
            "2",
            "-o",
            "c\x07.dmdjob.zip",
        ],
    );
    assert!(
        stdout(&o).starts_with("c\\u{7}.dmdjob.zip: "),
        "{:?}",
        stdout(&o)
    );
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
