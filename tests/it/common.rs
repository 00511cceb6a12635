//! Functions shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Path of the built `dmdsl` binary.
pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_dmdsl"))
}

/// Repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A fixture under `fixtures/`.
pub fn fixture(name: &str) -> PathBuf {
    root().join("fixtures").join(name)
}

/// A fresh, empty temporary directory for one test.
pub fn tempdir(name: &str) -> TempDir {
    let d = std::env::temp_dir().join(format!("dmdsl-it-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    TempDir(d)
}

/// A test's scratch directory: removed when the test passes, kept (for a look) when it
/// fails.
pub struct TempDir(PathBuf);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Runs `dmdsl` with `args` in directory `cwd`.
pub fn run_in(cwd: &Path, args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("run dmdsl")
}

/// Runs `dmdsl` with `args` in directory `cwd` on a pool of `threads` worker threads.
pub fn run_threads(cwd: &Path, args: &[&str], threads: &str) -> Output {
    Command::new(bin())
        .args(args)
        .env("RAYON_NUM_THREADS", threads)
        .current_dir(cwd)
        .output()
        .expect("run dmdsl")
}

/// Stderr as a string.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Stdout as a string.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Decodes an 8-bit grayscale PNG: (width, height, pixels).
pub fn read_gray(path: &Path) -> (u32, u32, Vec<u8>) {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let g = img.as_luma8().expect("8-bit grayscale").clone();
    (g.width(), g.height(), g.into_raw())
}

/// Writes a binary STL from triangles ([`dmdsl::mesh::binary_stl`]).
pub fn write_stl(path: &Path, tris: &[[[f32; 3]; 3]]) {
    std::fs::write(path, dmdsl::mesh::binary_stl(tris)).unwrap();
}

/// A 0.02 mm pin (a third of a default pixel: uncorrected its light peaks at a quarter of
/// the cure threshold) at field pixel (400, 300) beside a 100 px block, 0.3 mm (6 layers)
/// tall, written to `dir/pin.stl`: the STL and the pin's corner (build-plane mm).
pub fn tiny_pin_part(dir: &Path) -> (std::path::PathBuf, [f64; 2]) {
    let (tris, corner) = tiny_pin_tris();
    let model = dir.join("pin.stl");
    write_stl(&model, &tris);
    (model, corner)
}

/// The triangles of [`tiny_pin_part`] (the pin's 12 last) and the pin's corner.
pub fn tiny_pin_tris() -> (Vec<[[f32; 3]; 3]>, [f64; 2]) {
    let p = 65.0f32 / 1024.0; // the default pixel, 0.0634765625 mm
    let (x0, y0) = (400.0 * p, 300.0 * p);
    let mut tris = box_tris([200.0 * p, 200.0 * p, 0.0], [300.0 * p, 300.0 * p, 0.3]);
    tris.extend(box_tris([x0, y0, 0.0], [x0 + 0.02, y0 + 0.02, 0.3]));
    (tris, [x0 as f64, y0 as f64])
}

/// Triangles of an axis-aligned box [lo, hi], outward facing.
pub fn box_tris(lo: [f32; 3], hi: [f32; 3]) -> Vec<[[f32; 3]; 3]> {
    hexahedron(|i| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    })
}

/// Triangles of a square frustum centred on `centre` (x, y), standing on the platform:
/// half-width `bottom` at z = 0 and `top` at z = `height`, outward facing.
pub fn frustum_tris(centre: [f32; 2], bottom: f32, top: f32, height: f32) -> Vec<[[f32; 3]; 3]> {
    hexahedron(|i| {
        let half = if i & 4 == 0 { bottom } else { top };
        let side = |bit: usize| if i & bit == 0 { -half } else { half };
        [
            centre[0] + side(1),
            centre[1] + side(2),
            if i & 4 == 0 { 0.0 } else { height },
        ]
    })
}

/// Triangles of a solid of six quadrilateral faces whose corner `i` is `p(i)` (bits of
/// `i`: x, y, z high), the faces counter-clockwise from outside.
fn hexahedron(p: impl Fn(usize) -> [f32; 3]) -> Vec<[[f32; 3]; 3]> {
    let quads = [
        [0, 2, 3, 1], // z = lo
        [4, 5, 7, 6], // z = hi
        [0, 1, 5, 4], // y = lo
        [2, 6, 7, 3], // y = hi
        [0, 4, 6, 2], // x = lo
        [1, 3, 7, 5], // x = hi
    ];
    let mut t = Vec::new();
    for q in quads {
        t.push([p(q[0]), p(q[1]), p(q[2])]);
        t.push([p(q[0]), p(q[2]), p(q[3])]);
    }
    t
}

/// Every file under `dir` (relative path, bytes), sorted by path.
pub fn tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

/// The names in `dir`, sorted.
pub fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Sends `signal` (e.g. "INT", "TERM") to `child`.
pub fn signal(child: &std::process::Child, signal: &str) {
    let st = std::process::Command::new("kill")
        .args([&format!("-{signal}"), &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
}

/// The entries of the zip at `p`, in archive order, with their bytes (read with the zip
/// crate: an oracle independent of dmdsl's reader).
pub fn zip_entries(p: &Path) -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    zip_entries_of(&bytes).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// The entries of the zip `bytes`, in archive order, with their bytes (the zip crate).
pub fn zip_entries_of(bytes: &[u8]) -> zip::result::ZipResult<Vec<(String, Vec<u8>)>> {
    use std::io::Read;
    let mut z = zip::ZipArchive::new(std::io::Cursor::new(bytes))?;
    Ok((0..z.len())
        .map(|i| {
            let mut e = z.by_index(i).unwrap();
            let mut b = Vec::new();
            e.read_to_end(&mut b).unwrap();
            (String::from_utf8_lossy(e.name_raw()).into_owned(), b)
        })
        .collect())
}

/// The warnings of `code` in a `--json` summary or a manifest.
pub fn warnings_of<'a>(v: &'a serde_json::Value, code: &str) -> Vec<&'a serde_json::Value> {
    v["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|w| w["code"] == code)
        .collect()
}

/// Runs `dmdsl` with `args` in `cwd` under resource limits set in the child before it
/// starts (`setrlimit`: `RLIMIT_AS` address space, `RLIMIT_FSIZE` largest file written,
/// with SIGXFSZ ignored so a write past it fails with EFBIG, as on a full disk), and its
/// peak resident memory in bytes: the output, the exit code and the peak. The peak is the
/// program's own `VmHWM`, read from `/proc` while it runs (monotonic, so the last reading
/// before it exits is its peak): `wait4`'s `ru_maxrss` would also count the resident size
/// of this test process at the fork, which other tests running beside it make large.
#[cfg(target_os = "linux")]
pub fn run_limited(
    cwd: &Path,
    args: &[&str],
    address_space: Option<u64>,
    file_size: Option<u64>,
) -> (Output, Option<i32>, u64) {
    use std::io::Read;
    use std::os::unix::process::{CommandExt, ExitStatusExt};
    let mut cmd = Command::new(bin());
    cmd.args(args)
        .current_dir(cwd)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    // SAFETY: between fork and exec only async-signal-safe calls (setrlimit, signal).
    unsafe {
        cmd.pre_exec(move || {
            let set = |what, v: u64| {
                let l = libc::rlimit {
                    rlim_cur: v,
                    rlim_max: v,
                };
                if libc::setrlimit(what, &l) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            };
            if let Some(v) = address_space {
                set(libc::RLIMIT_AS, v)?;
            }
            if let Some(v) = file_size {
                set(libc::RLIMIT_FSIZE, v)?;
                libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            }
            Ok(())
        });
    }
    // Waited for by `wait4` below, which also gives its resource use.
    #[allow(clippy::zombie_processes)]
    let mut child = cmd.spawn().expect("run dmdsl");
    let pid = child.id();
    let watch = std::thread::spawn(move || {
        let mut peak = 0;
        // Until the program has exited (a zombie's status has no memory lines); readings
        // before its exec (the forked copy of this process) are left out by name.
        while let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) {
            let field = |k: &str| {
                status
                    .lines()
                    .find_map(|l| l.strip_prefix(k))
                    .map(str::trim)
            };
            let Some(hwm) = field("VmHWM:") else { break };
            if field("Name:") == Some("dmdsl") {
                let kb: u64 = hwm.trim_end_matches("kB").trim().parse().unwrap_or(0);
                peak = peak.max(kb * 1024);
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        peak
    });
    let (mut out, mut err) = (Vec::new(), Vec::new());
    child.stdout.take().unwrap().read_to_end(&mut out).unwrap();
    child.stderr.take().unwrap().read_to_end(&mut err).unwrap();
    let peak = watch.join().unwrap();
    let (mut status, mut usage) = (0, unsafe { std::mem::zeroed::<libc::rusage>() });
    // SAFETY: waits for this child only; `status` and `usage` are valid for writes.
    let pid = unsafe { libc::wait4(child.id() as i32, &mut status, 0, &mut usage) };
    assert_eq!(pid, child.id() as i32, "wait4");
    let status = std::process::ExitStatus::from_raw(status);
    let output = Output {
        status,
        stdout: out,
        stderr: err,
    };
    (output, status.code(), peak)
}

/// The regions of `cur` that rest on nothing in `below` (`w × h` lit flags, row-major), by
/// a flood fill of the pixels, apart from dmdsl's run-based counters: (pixels, mean
/// column, mean row) of each 4-connected region none of whose pixels is lit below (pixel
/// centres at +0.5).
pub fn regions_on_nothing(
    cur: &[bool],
    below: &[bool],
    w: usize,
    h: usize,
) -> Vec<(u64, f64, f64)> {
    let mut seen = vec![false; w * h];
    let mut out = Vec::new();
    for s in 0..w * h {
        if !cur[s] || seen[s] {
            continue;
        }
        seen[s] = true;
        let (mut stack, mut rests) = (vec![s], false);
        let (mut n, mut sc, mut sr) = (0u64, 0.0, 0.0);
        while let Some(k) = stack.pop() {
            rests |= below[k];
            let (r, c) = (k / w, k % w);
            (n, sc, sr) = (n + 1, sc + c as f64 + 0.5, sr + r as f64 + 0.5);
            let near = [
                (r > 0).then(|| k - w),
                (r + 1 < h).then(|| k + w),
                (c > 0).then(|| k - 1),
                (c + 1 < w).then(|| k + 1),
            ];
            for q in near.into_iter().flatten() {
                if cur[q] && !seen[q] {
                    seen[q] = true;
                    stack.push(q);
                }
            }
        }
        if !rests {
            out.push((n, sc / n as f64, sr / n as f64));
        }
    }
    out
}

/// Exports the job `job` in `dir` to the SLA control-file standard (`<job>.control.zip`)
/// and checks that `run` replays both alike: the same exposure and light time, no
/// violation (an exposure longer than the schema allows becomes several images, so the
/// export may have more layers).
pub fn assert_exports_to_control(dir: &Path, job: &str) {
    let zip = format!("{job}.control.zip");
    let o = run_in(dir, &["export", job, "--format", "sla-control", "-o", &zip]);
    assert!(o.status.success(), "export {job}: {}", stderr(&o));
    let report = |b: &str| -> serde_json::Value {
        let o = run_in(dir, &["run", b, "--json"]);
        assert!(o.status.success(), "run {b}: {}{}", stdout(&o), stderr(&o));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let (a, b) = (report(job), report(&zip));
    assert_eq!(b["format"], "sla-control");
    for k in ["exposure_s", "light_on_s"] {
        assert_eq!(a[k], b[k], "{job}: {k}");
    }
    assert!(b["layers"].as_u64() >= a["layers"].as_u64(), "{job}: {b}");
}

/// `cure.predicted` of the job `slice fixtures/features.stl --predict -o OUT` with
/// `extra` arguments writes in `dir` (the command must succeed).
pub fn predicted_cure(dir: &Path, out: &str, extra: &[&str]) -> serde_json::Value {
    let part = fixture("features.stl");
    let mut args = vec!["slice", part.to_str().unwrap(), "--predict", "-o", out];
    args.extend_from_slice(extra);
    let o = run_in(dir, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join(out).join("job.json")).unwrap()).unwrap();
    j["cure"]["predicted"].clone()
}

/// A command whose child starts with the stop signals (SIGINT, SIGTERM, SIGHUP) at their
/// default disposition: dmdsl leaves a signal ignored when it starts ignored (under
/// `nohup`, in a background job of a shell), and the tests that send them must not depend
/// on how the test run itself was started.
pub trait Stoppable {
    /// Resets the stop signals in the child before it runs.
    fn stoppable(&mut self) -> &mut Self;
}

impl Stoppable for Command {
    fn stoppable(&mut self) -> &mut Self {
        use std::os::unix::process::CommandExt;
        // SAFETY: signal() is async-signal-safe, and nothing else runs in the child
        // between fork and exec.
        unsafe {
            self.pre_exec(|| {
                for s in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
                    libc::signal(s, libc::SIG_DFL);
                }
                Ok(())
            })
        }
    }
}

/// Asserts that every decimal number in the fit file `text` has at most 7 significant
/// digits: a fit is written to what it knows, not with its floating-point noise.
pub fn assert_rounded_numbers(text: &str) {
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.contains("sha256"))
    {
        for word in line.split([' ', ',', '[', ']']) {
            if word.contains('.') && word.parse::<f64>().is_ok() {
                let digits = word.trim_start_matches(['-', '0', '.']).replace('.', "");
                assert!(digits.len() <= 7 && !word.contains('e'), "{word}: {line}");
            }
        }
    }
}
