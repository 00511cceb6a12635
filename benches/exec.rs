//! Benchmark of the dry-run executor (`dmdsl run`) on a synthetic job.
//!
//! `cargo bench --bench exec -- [LAYERS] [REPEATS]` (defaults 10000 and 20) builds a
//! LAYERS-layer top-down job for the default profile (0.01 mm layers, natural-leveling
//! recoat: dip 5 mm, return, wait, expose) as a real bundle in a temporary directory:
//! `job.json` plus one 1024×768 8-bit mask PNG per layer (disks of varying radius,
//! encoded like the slicer does). It then times, each as the median (and min) of REPEATS
//! runs unless noted:
//! * parsing job.json (`Manifest::read`);
//! * simulating all layers with the invariant checker (no files), the requirement being
//!   "well under a second" for 10,000 layers;
//! * simulating with the CSV trace streamed to a file;
//! * verifying all masks (read + SHA-256 + PNG decode) with 1 thread and with all threads
//!   (3 runs each, the files are in the page cache after the first);
//! * the whole `exec::run` as `dmdsl run` does it (3 runs).

use dmdsl::bundle::*;
use dmdsl::exec::{self, check::Checker, sim, testutil, trace::TraceWriter, RunOptions};
use dmdsl::motion::move_time;
use dmdsl::profile::Profile;
use dmdsl::raster::Mask;
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let n: usize = args.first().and_then(|a| a.parse().ok()).unwrap_or(10_000);
    let reps: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(20);
    let dir = std::env::temp_dir().join(format!("dmdsl-bench-exec-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let bundle = dir.join("synthetic.dmdjob");

    let t = Instant::now();
    let manifest = synthetic(&bundle, n);
    println!(
        "built {n}-layer bundle in {:.2} s ({} threads)",
        t.elapsed().as_secs_f64(),
        rayon::current_num_threads()
    );

    let (med, min) = time(reps, || {
        Manifest::read(&bundle).unwrap();
    });
    row("read job.json", med, min, reps);

    let mut total = 0.0;
    let (med, min) = time(reps, || {
        let mut c = Checker::new(&manifest);
        let o = sim::simulate(&manifest, &[], &mut [&mut c]);
        let v = c.finish(o.total_s, true);
        assert!(v.is_empty(), "{:?}", &v[..v.len().min(3)]);
        total = o.total_s;
    });
    row("simulate + check", med, min, reps);
    println!(
        "  simulated job time {:.1} h, estimate {:.1} h",
        total / 3600.0,
        manifest.totals.print_time_s / 3600.0
    );

    let trace = dir.join("trace.csv");
    let m = sim::Machine::of(&manifest.machine);
    let mut rows = 0;
    let (med, min) = time(reps.min(5), || {
        let mut c = Checker::new(&manifest);
        let mut w = TraceWriter::create(&trace, None, m).unwrap();
        sim::simulate(&manifest, &[], &mut [&mut c, &mut w]);
        rows = w.finish().unwrap();
    });
    row("simulate + check + trace", med, min, reps.min(5));
    println!(
        "  trace: {rows} rows, {:.1} MB",
        std::fs::metadata(&trace).unwrap().len() as f64 / 1e6
    );

    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let c0 = cpu_s();
    let (med1, min1) = time(3, || {
        one.install(|| assert!(exec::verify::verify(&bundle, &manifest).problems.is_empty()))
    });
    let cpu1 = (cpu_s() - c0) / 3.0;
    row("verify masks, 1 thread", med1, min1, 3);
    let c0 = cpu_s();
    let (medn, minn) = time(3, || {
        assert!(exec::verify::verify(&bundle, &manifest).problems.is_empty())
    });
    let cpun = (cpu_s() - c0) / 3.0;
    row("verify masks, all threads", medn, minn, 3);
    println!(
        "  wall-clock speed-up {:.2}x; CPU time per run {:.2} s (1 thread), {:.2} s (all); {:.3} ms CPU per mask",
        med1 / medn,
        cpu1,
        cpun,
        cpu1 / n as f64 * 1e3
    );

    let (med, min) = time(3, || {
        let r = exec::run(&bundle, &RunOptions::default()).unwrap();
        assert!(r.ok);
    });
    row("exec::run (whole dmdsl run)", med, min, 3);
    let _ = std::fs::remove_dir_all(&dir);
}

/// CPU time (user + system) of this process so far, s (Linux /proc; 0 elsewhere).
fn cpu_s() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which is in parentheses): utime and stime are the
    // 12th and 13th, in clock ticks (100 per second on Linux).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}

fn row(what: &str, med: f64, min: f64, reps: usize) {
    println!(
        "{what:<32} median {:>9.2} ms   min {:>9.2} ms   ({reps} runs)",
        med * 1e3,
        min * 1e3
    );
}

fn time(reps: usize, mut f: impl FnMut()) -> (f64, f64) {
    let mut v: Vec<f64> = (0..reps.max(1))
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

/// A disk mask (anti-aliased edge) of radius `r` px, encoded like the slicer does.
fn disk_png(r: f64) -> Vec<u8> {
    let (w, h) = (1024u32, 768u32);
    let mut data = vec![0u8; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let d = ((x as f64 - 512.0).powi(2) + (y as f64 - 384.0).powi(2)).sqrt();
            data[(y * w + x) as usize] = ((r - d + 0.5).clamp(0.0, 1.0) * 255.0) as u8;
        }
    }
    dmdsl::job::encode_png(&Mask {
        width: w,
        height: h,
        data,
    })
}

/// Writes a bundle of `n` layers at `path` and returns its manifest.
fn synthetic(path: &Path, n: usize) -> Manifest {
    let profile = Profile::default_profile();
    let h = 0.01;
    let p = profile.field().pixel_mm;
    let pngs: Vec<(Vec<u8>, String, f64)> = (0..16)
        .map(|k| {
            let r = 60.0 + 20.0 * k as f64;
            let b = disk_png(r);
            let s = sha256_hex(&b);
            (b, s, r)
        })
        .collect();
    let w = BundleWriter::create(path).unwrap();
    let st = &profile.stage;
    let r = profile.recoat.clone().unwrap();
    let (a, o, c) = (
        st.max_accel_mm_s2.get(),
        profile.shutter.open_s.get(),
        profile.shutter.close_s.get(),
    );
    let mut pos = st.home_mm;
    let mut layers = Vec::with_capacity(n);
    for i in 0..n {
        let z = (i + 1) as f64 * h;
        let exposure_s = profile.exposure.layer_exposure_s(i);
        let steps = vec![
            Step::Move {
                to_mm: z + r.dip_mm.get(),
                speed_mm_s: r.dip_speed_mm_s.get(),
                accel_mm_s2: a,
            },
            Step::Move {
                to_mm: z,
                speed_mm_s: r.return_speed_mm_s.get(),
                accel_mm_s2: a,
            },
            Step::Wait { s: r.wait_s.get() },
            Step::Expose { s: exposure_s },
        ];
        // Estimate under the timing contract (the DMD load hides behind the first move).
        let time_s = move_time(z + r.dip_mm.get() - pos, r.dip_speed_mm_s.get(), a)
            + move_time(r.dip_mm.get(), r.return_speed_mm_s.get(), a)
            + r.wait_s.get()
            + o
            + exposure_s
            + c;
        pos = z;
        let (png, sha, r) = &pngs[i % pngs.len()];
        let mut layer = testutil::layer(i, z, h, Mode::Layered, exposure_s, steps, time_s);
        // The disk's section: centre (512.5, 383.5) px from the bottom-left, its pixels lit
        // up to r + 0.5 px from the centre.
        let (cx, cy, re) = (512.5 * p, 383.5 * p, (r + 0.5) * p);
        layer.area_mm2 = std::f64::consts::PI * re * re;
        layer.bbox_mm = Some([[cx - re, cy - re], [cx + re, cy + re]]);
        layer.masks[0].sha256 = sha.clone();
        w.write_file(&layer.masks[0].file, png).unwrap();
        layers.push(layer);
    }
    let manifest = testutil::manifest(profile, layers);
    w.finish(&manifest).unwrap();
    manifest
}
