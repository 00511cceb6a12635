//! Projector geometry as a user meets it: `slice --distortion TABLE.csv`, `[distortion]` in
//! a profile, and the errors a bad table or an unreachable part give.
//!
//! The landing tests generate a known forward distortion (what the lens does), measure it
//! into a table with noise (what the machine's owner does), slice 3 mm squares through the
//! correction, decode the masks and push every lit pixel through the TRUE forward map: the
//! squares' centroids must land within 0.05 mm (max) and 0.025 mm (RMS) of where the file
//! put them.

use crate::common::*;
use serde_json::Value;
use std::path::Path;

const P: f64 = 65.0 / 1024.0;
const W: f64 = 65.0;
const H: f64 = 48.75;

/// xorshift64* with Box–Muller: fixed seeds, no dependencies.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let u = self.uniform().max(1e-300);
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * self.uniform()).cos()
    }
}

/// A held-out "true" lens: where light aimed at `p` lands.
#[derive(Clone, Copy, Debug)]
enum Lens {
    /// Radial about the centre, corners moved by `k` × the half-diagonal (k < 0: barrel).
    Radial(f64),
    /// Projective keystone (tilted projector) plus a small rotation and shift (assembly).
    Keystone,
}

impl Lens {
    fn forward(self, p: [f64; 2]) -> [f64; 2] {
        let (cx, cy) = (W / 2.0, H / 2.0);
        let (dx, dy) = (p[0] - cx, p[1] - cy);
        match self {
            Lens::Radial(k) => {
                let r2 = (dx * dx + dy * dy) / (cx * cx + cy * cy);
                let s = 1.0 + k * r2;
                [cx + dx * s, cy + dy * s]
            }
            Lens::Keystone => {
                let w = 1.0 + 0.01 * dx / cx + 0.04 * dy / cy;
                let (x, y) = (dx / w, dy / w);
                let a = 0.2f64.to_radians();
                [
                    cx + 0.3 + x * a.cos() - y * a.sin(),
                    cy - 0.2 + x * a.sin() + y * a.cos(),
                ]
            }
        }
    }

    /// |det J| of the forward map at `p`.
    fn jacobian(self, p: [f64; 2]) -> f64 {
        let e = 1e-4;
        let fx0 = self.forward([p[0] - e, p[1]]);
        let fx1 = self.forward([p[0] + e, p[1]]);
        let fy0 = self.forward([p[0], p[1] - e]);
        let fy1 = self.forward([p[0], p[1] + e]);
        let a = (fx1[0] - fx0[0]) / (2.0 * e);
        let b = (fy1[0] - fy0[0]) / (2.0 * e);
        let c = (fx1[1] - fx0[1]) / (2.0 * e);
        let d = (fy1[1] - fy0[1]) / (2.0 * e);
        (a * d - b * c).abs()
    }
}

/// The measured table: a 14 × 10 grid of aim points over the field (5 mm apart), each seen
/// through the lens with Gaussian noise of `noise` mm per coordinate.
fn write_table(path: &Path, lens: Lens, noise: f64, seed: u64) {
    let mut rng = Rng(seed);
    let mut s = String::from("x_mm,y_mm,seen_x_mm,seen_y_mm\n");
    for j in 0..=9 {
        for i in 0..=13 {
            let aim = [i as f64 * W / 13.0, j as f64 * H / 9.0];
            let f = lens.forward(aim);
            s.push_str(&format!(
                "{:.4},{:.4},{:.4},{:.4}\n",
                aim[0],
                aim[1],
                f[0] + noise * rng.gauss(),
                f[1] + noise * rng.gauss()
            ));
        }
    }
    std::fs::write(path, s).unwrap();
}

/// Centres of the 3 mm test squares: a 5 × 4 grid from 8 mm to 57 × 40 mm.
fn centres() -> Vec<[f64; 2]> {
    let mut v = Vec::new();
    for j in 0..4 {
        for i in 0..5 {
            v.push([8.0 + i as f64 * 12.25, 8.0 + j as f64 * 10.25]);
        }
    }
    v
}

fn write_squares(path: &Path, centres: &[[f64; 2]]) {
    let mut tris = Vec::new();
    for c in centres {
        tris.extend(box_tris(
            [c[0] as f32 - 1.5, c[1] as f32 - 1.5, 0.0],
            [c[0] as f32 + 1.5, c[1] as f32 + 1.5, 0.12],
        ));
    }
    write_stl(path, &tris);
}

fn slice(dir: &Path, args: &[&str]) -> Value {
    let o = run_in(dir, args);
    assert!(o.status.success(), "dmdsl {args:?}: {}", stderr(&o));
    let out = args.iter().position(|a| *a == "-o").unwrap() + 1;
    serde_json::from_slice(&std::fs::read(dir.join(args[out]).join("job.json")).unwrap()).unwrap()
}

/// Landing error (mm) of each square's area centroid: every lit pixel, weighted by its
/// coverage and the area the lens gives it, pushed through the true forward map, and
/// assigned to the nearest intended centre.
fn landing_errors(mask: &[u8], lens: Lens, centres: &[[f64; 2]]) -> Vec<f64> {
    let mut acc = vec![[0.0f64; 3]; centres.len()];
    for r in 0..768usize {
        for c in 0..1024usize {
            let v = mask[r * 1024 + c] as f64;
            if v == 0.0 {
                continue;
            }
            let p = [(c as f64 + 0.5) * P, H - (r as f64 + 0.5) * P];
            let f = lens.forward(p);
            let w = v * lens.jacobian(p);
            let k = (0..centres.len())
                .min_by(|&a, &b| {
                    let da = (centres[a][0] - f[0]).hypot(centres[a][1] - f[1]);
                    let db = (centres[b][0] - f[0]).hypot(centres[b][1] - f[1]);
                    da.total_cmp(&db)
                })
                .unwrap();
            acc[k][0] += w * f[0];
            acc[k][1] += w * f[1];
            acc[k][2] += w;
        }
    }
    acc.iter()
        .zip(centres)
        .map(|(a, c)| {
            assert!(a[2] > 0.0, "square at {c:?} missing");
            (a[0] / a[2] - c[0]).hypot(a[1] / a[2] - c[1])
        })
        .collect()
}

fn layer0(dir: &Path, bundle: &str, job: &Value) -> Vec<u8> {
    let f = job["layers"][0]["masks"][0]["file"].as_str().unwrap();
    read_gray(&dir.join(bundle).join(f)).2
}

#[test]
fn squares_land_within_0_05_mm_through_held_out_distortions() {
    let dir = tempdir("geom-land");
    let cs = centres();
    write_squares(&dir.join("sq.stl"), &cs);
    let mut all = Vec::new();
    for (n, lens) in [Lens::Radial(-0.05), Lens::Radial(0.05), Lens::Keystone]
        .into_iter()
        .enumerate()
    {
        let corner = (0..4)
            .map(|i| {
                let p = [(i & 1) as f64 * W, (i >> 1) as f64 * H];
                let f = lens.forward(p);
                (f[0] - p[0]).hypot(f[1] - p[1])
            })
            .fold(0.0, f64::max);
        assert!(
            (1.5..=2.5).contains(&corner),
            "{lens:?}: corners off by {corner}"
        );
        let table = format!("t{n}.csv");
        write_table(&dir.join(&table), lens, 0.01, 17 + n as u64);
        let out = format!("d{n}.dmdjob");
        let job = slice(
            &dir,
            &[
                "slice",
                "sq.stl",
                "--keep-position",
                "--compensation",
                "off",
                "--distortion",
                &table,
                "-q",
                "-o",
                &out,
            ],
        );
        let rep = &job["settings"]["distortion"];
        assert_eq!(rep["source"], table.as_str());
        assert_eq!(rep["points"], 140);
        assert!(rep["cv_rms_mm"].as_f64().unwrap() < 0.03, "{rep}");
        let errs = landing_errors(&layer0(&dir, &out, &job), lens, &cs);
        let max = errs.iter().cloned().fold(0.0, f64::max);
        eprintln!("{lens:?}: corrected max landing error {max:.4} mm");
        assert!(
            max <= 0.05,
            "{lens:?}: max landing error {max} mm: {errs:?}"
        );
        all.extend(errs);

        // Without the correction the same squares land far off: the test can fail.
        let raw = format!("r{n}.dmdjob");
        let job = slice(
            &dir,
            &[
                "slice",
                "sq.stl",
                "--keep-position",
                "--compensation",
                "off",
                "-q",
                "-o",
                &raw,
            ],
        );
        let errs = landing_errors(&layer0(&dir, &raw, &job), lens, &cs);
        let max = errs.iter().cloned().fold(0.0, f64::max);
        eprintln!("{lens:?}: uncorrected max landing error {max:.3} mm");
        assert!(max > 0.5, "{lens:?}: uncorrected max error only {max} mm");
    }
    let rms = (all.iter().map(|e| e * e).sum::<f64>() / all.len() as f64).sqrt();
    eprintln!("RMS landing error over {} squares: {rms:.4} mm", all.len());
    assert!(rms <= 0.025, "RMS landing error {rms} mm");
}

#[test]
fn distortion_in_profile_relative_table_and_inline_points() {
    let dir = tempdir("geom-profile");
    std::fs::create_dir_all(dir.join("machine")).unwrap();
    write_table(&dir.join("machine/lens.csv"), Lens::Radial(0.05), 0.0, 1);
    let base = run_in(&dir, &["profile", "show", "xu2010-topdown"]);
    let src = stdout(&base);
    std::fs::write(
        dir.join("machine/p.toml"),
        format!("{src}\n[distortion]\ntable = \"lens.csv\"\n"),
    )
    .unwrap();
    write_squares(&dir.join("sq.stl"), &[[30.0, 20.0]]);
    let a = slice(
        &dir,
        &[
            "slice",
            "sq.stl",
            "--profile",
            "machine/p.toml",
            "-q",
            "-o",
            "a.dmdjob",
        ],
    );
    assert_eq!(a["settings"]["distortion"]["source"], "lens.csv");
    // The masks are pre-warped: the job's machine record holds no table.
    assert!(a["machine"].get("distortion").is_none());

    // The same points inline in a profile give the same masks.
    let table = std::fs::read_to_string(dir.join("machine/lens.csv")).unwrap();
    let inline: Vec<String> = table
        .lines()
        .skip(1)
        .map(|row| format!("[{}]", row.replace(',', ", ")))
        .collect();
    assert_eq!(inline.len(), 140);
    std::fs::write(
        dir.join("q.toml"),
        format!("{src}\n[distortion]\npoints = [{}]\n", inline.join(", ")),
    )
    .unwrap();
    let b = slice(
        &dir,
        &[
            "slice",
            "sq.stl",
            "--profile",
            "q.toml",
            "-q",
            "-o",
            "b.dmdjob",
        ],
    );
    assert_eq!(
        a["layers"][0]["masks"][0]["sha256"],
        b["layers"][0]["masks"][0]["sha256"]
    );
    assert_eq!(
        b["settings"]["distortion"]["source"],
        "profile xu2010-topdown"
    );

    // `--distortion off` ignores the profile's table; no correction → plain masks.
    let c = slice(
        &dir,
        &[
            "slice",
            "sq.stl",
            "--profile",
            "machine/p.toml",
            "--distortion",
            "off",
            "-q",
            "-o",
            "c.dmdjob",
        ],
    );
    let d = slice(&dir, &["slice", "sq.stl", "-q", "-o", "d.dmdjob"]);
    assert!(c["settings"].get("distortion").is_none());
    assert!(c["machine"].get("distortion").is_none());
    assert_eq!(
        c["layers"][0]["masks"][0]["sha256"],
        d["layers"][0]["masks"][0]["sha256"]
    );
    assert_ne!(
        a["layers"][0]["masks"][0]["sha256"],
        d["layers"][0]["masks"][0]["sha256"]
    );
    // The human summary reports the fit.
    let o = run_in(
        &dir,
        &[
            "slice",
            "sq.stl",
            "--profile",
            "machine/p.toml",
            "-o",
            "e.dmdjob",
        ],
    );
    assert!(o.status.success());
    assert!(
        stdout(&o).contains("distortion lens.csv: 140 points, degree-"),
        "{}",
        stdout(&o)
    );
}

#[test]
fn bad_tables_and_unreachable_parts_exit_2_with_one_line() {
    let dir = tempdir("geom-bad");
    write_squares(&dir.join("sq.stl"), &[[1.6, 1.6]]);
    let cases: &[(&str, &str, &str)] = &[
        (
            "cols.csv",
            "x_mm,y_mm,seen_x_mm,seen_y_mm\n1,2,3,4\n5,6,7\n",
            "cols.csv: line 3: expected 4 columns (x_mm,y_mm,seen_x_mm,seen_y_mm), found 3",
        ),
        (
            "num.csv",
            "1,2,3,4\n5,6,seven,8\n",
            "num.csv: line 2, column seen_x_mm: \"seven\" is not a number",
        ),
        (
            "few.csv",
            "1,2,3,4\n5,6,7,8\n",
            "few.csv: a distortion table needs at least 6 points, found 2",
        ),
    ];
    for (name, text, want) in cases {
        std::fs::write(dir.join(name), text).unwrap();
        let o = run_in(
            &dir,
            &[
                "slice",
                "sq.stl",
                "--keep-position",
                "--distortion",
                name,
                "-o",
                "x.dmdjob",
            ],
        );
        assert_eq!(o.status.code(), Some(2), "{name}");
        let e = stderr(&o);
        assert!(e.contains(want), "{name}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(!dir.join("x.dmdjob").exists());
    }
    let o = run_in(
        &dir,
        &[
            "slice",
            "sq.stl",
            "--keep-position",
            "--distortion",
            "missing.csv",
            "-o",
            "x.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("missing.csv"), "{}", stderr(&o));

    // Barrel: the corner square is outside what the projector can reach.
    write_table(&dir.join("barrel.csv"), Lens::Radial(-0.05), 0.0, 1);
    let o = run_in(
        &dir,
        &[
            "slice",
            "sq.stl",
            "--keep-position",
            "--distortion",
            "barrel.csv",
            "-o",
            "x.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("sq.stl: layer 0: build-plane point ("), "{e}");
    assert!(e.contains(" mm cannot be reached: with the distortion correction (barrel.csv) the projector would have to aim at ("), "{e}");
    assert!(e.contains("outside its field 0..65 x 0..48.75 mm"), "{e}");
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    assert!(!dir.join("x.dmdjob").exists());

    // Tables that fit but cannot be right: a mirror image of the field (the map folds over:
    // warped sections turn inside out), a 35 mm outlier, a point measured twice far apart.
    let grid: Vec<[f64; 2]> = (0..=13)
        .flat_map(|i| (0..=9).map(move |j| [5.0 * i as f64, 5.0 * j as f64 * 0.975]))
        .collect();
    let table = |f: &dyn Fn(usize, [f64; 2]) -> [f64; 2]| {
        let mut t = String::from("x_mm,y_mm,seen_x_mm,seen_y_mm\n");
        for (i, &p) in grid.iter().enumerate() {
            let s = f(i, p);
            t += &format!("{},{},{},{}\n", p[0], p[1], s[0], s[1]);
        }
        t
    };
    let mirror = table(&|_, p| [W - p[0], p[1]]);
    let outlier = table(&|i, p| {
        let off = if i == 40 { [35.3, 0.7] } else { [0.0; 2] };
        [p[0] + off[0], p[1] + off[1]]
    });
    let mut twice = table(&|_, p| p);
    twice += &format!(
        "{},{},{},{}\n",
        grid[50][0],
        grid[50][1],
        grid[50][0] + 3.0,
        grid[50][1] - 2.0
    );
    for (name, text, want) in [
        (
            "mirror.csv",
            mirror,
            "mirror.csv: the correction folds the field over",
        ),
        (
            "outlier.csv",
            outlier,
            "from where the rest of the table predicts them, worst line 42 (35.3",
        ),
        (
            "twice.csv",
            twice,
            "more than 1 mm from where the rest of the table predicts",
        ),
    ] {
        std::fs::write(dir.join(name), text).unwrap();
        let o = run_in(
            &dir,
            &["slice", "sq.stl", "--distortion", name, "-o", "x.dmdjob"],
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{name}: {e}");
        assert!(e.contains(want), "{name}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(!dir.join("x.dmdjob").exists());
    }
}

#[test]
fn a_job_warped_beyond_its_table_is_the_same_at_any_thread_count() {
    // A table measured over the middle of the field only: the bunny's edges are warped by
    // extrapolation, and the count of such points (the cure correction's layers warp the
    // sections above them too) must not depend on which worker warped a section first.
    let dir = tempdir("geom-threads");
    let mut t = String::from("x_mm,y_mm,seen_x_mm,seen_y_mm\n");
    for j in 0..6 {
        for i in 0..8 {
            let (x, y) = (15.0 + 5.0 * i as f64, 12.0 + 5.0 * j as f64);
            t.push_str(&format!(
                "{x},{y},{},{}\n",
                x + 0.001 * i as f64,
                y + 0.001 * j as f64
            ));
        }
    }
    std::fs::write(dir.join("inner.csv"), t).unwrap();
    let bunny = fixture("bunny00.stl");
    let job = |threads: &str| {
        let out = format!("t{threads}.dmdjob.zip");
        let args = [
            "slice",
            bunny.to_str().unwrap(),
            "--distortion",
            "inner.csv",
            "-o",
            &out,
        ];
        let o = run_threads(&dir, &args, threads);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(
            stderr(&o).contains("[distortion.extrapolated]"),
            "{}",
            stderr(&o)
        );
        std::fs::read(dir.join(out)).unwrap()
    };
    let one = job("1");
    assert!(
        job("3") == one,
        "the job on 3 threads differs from the job on one"
    );
}

#[test]
fn an_unreachable_part_names_its_lowest_failing_layer_at_any_thread_count() {
    // A column in reach, and from layer 7 (z 0.35 mm) a slab out to x = 0.3 mm, beyond
    // the barrel's reach: every layer from 7 up fails, and so does a layer below whose
    // cure correction looks up at them. On 8 threads the block of layers 8–15 fails at
    // once while the block below is still at work: the error must still be the lowest
    // layer's, as one thread finds it.
    let dir = tempdir("geom-lowest");
    let mut tris = box_tris([20.0, 20.0, 0.0], [30.0, 28.0, 1.0]);
    tris.extend(box_tris([0.3, 20.0, 0.35], [40.0, 28.0, 1.0]));
    write_stl(&dir.join("part.stl"), &tris);
    write_table(&dir.join("barrel.csv"), Lens::Radial(-0.05), 0.0, 1);
    let args = [
        "slice",
        "part.stl",
        "--keep-position",
        "--distortion",
        "barrel.csv",
        "-o",
        "x.dmdjob",
    ];
    let one = run_threads(&dir, &args, "1");
    assert_eq!(one.status.code(), Some(2));
    let e = stderr(&one);
    assert!(e.contains("part.stl: layer 7: build-plane point ("), "{e}");
    for _ in 0..3 {
        let o = run_threads(&dir, &args, "8");
        assert_eq!(o.status.code(), Some(2));
        assert_eq!(stderr(&o), e);
        assert!(!dir.join("x.dmdjob").exists());
    }
}

/// Slices a 30 × 20 mm plate across the seam of `tiled-2x1` (field columns ~788..1260; the
/// overlap is 992..1024) with `profile`; returns the two projector masks of layer 0.
fn tiled_plate(dir: &Path, profile: &str, out: &str) -> (Vec<u8>, Vec<u8>) {
    write_stl(
        &dir.join("plate.stl"),
        &box_tris([50.0, 10.0, 0.0], [80.0, 30.0, 0.12]),
    );
    let job = slice(
        dir,
        &[
            "slice",
            "plate.stl",
            "--keep-position",
            "--profile",
            profile,
            "-q",
            "-o",
            out,
        ],
    );
    let masks = job["layers"][0]["masks"].as_array().unwrap();
    assert_eq!(masks.len(), 2);
    dmdsl::bundle::Manifest::read(&dir.join(out)).expect("manifest reads back");
    let mut px = Vec::new();
    for (k, m) in masks.iter().enumerate() {
        assert_eq!(m["projector"], k);
        assert_eq!(m["file"], format!("masks/p{k}/00000.png"));
        let (w, h, data) = read_gray(&dir.join(out).join(m["file"].as_str().unwrap()));
        assert_eq!((w, h), (1024, 768));
        px.push(data);
    }
    let b = px.pop().unwrap();
    (px.pop().unwrap(), b)
}

/// Field column `c` of row `r` as (p0 gray, p1 gray), 0 where a projector does not reach.
fn at(a: &[u8], b: &[u8], r: usize, c: usize) -> (i32, i32) {
    let va = if c < 1024 { a[r * 1024 + c] as i32 } else { 0 };
    let vb = if c >= 992 {
        b[r * 1024 + c - 992] as i32
    } else {
        0
    };
    (va, vb)
}

/// Plate columns and rows well inside its edges.
const PLATE_COLS: std::ops::Range<usize> = 792..1256;
const PLATE_ROWS: std::ops::Range<usize> = 300..450;

#[test]
fn tiled_2x1_seam_sums_to_255_and_is_smooth() {
    let dir = tempdir("geom-tiled");
    for (profile, name) in [("tiled-2x1", "default"), ("eehm.toml", "eehm")] {
        if name == "eehm" {
            let src = stdout(&run_in(&dir, &["profile", "show", "tiled-2x1"]));
            let src = src.replace("curve = \"raised-cosine\"", "curve = \"eehm\"");
            std::fs::write(dir.join("eehm.toml"), src).unwrap();
        }
        let (a, b) = tiled_plate(&dir, profile, &format!("{name}.dmdjob"));
        let mut worst_sum = 0;
        let mut worst_step = 0;
        for r in PLATE_ROWS {
            for c in PLATE_COLS {
                let (va, vb) = at(&a, &b, r, c);
                if (992..1024).contains(&c) {
                    worst_sum = worst_sum.max((va + vb - 255).abs());
                } else {
                    assert_eq!(va + vb, 255, "{name}: col {c} outside the overlap");
                }
                if c + 1 < PLATE_COLS.end {
                    let (na, nb) = at(&a, &b, r, c + 1);
                    worst_step = worst_step.max((na - va).abs()).max((nb - vb).abs());
                }
            }
        }
        assert!(worst_sum <= 2, "{name}: overlap sum off by {worst_sum}");
        // p0 fades out across the overlap while p1 fades in, crossing near the middle.
        let (l, r) = (at(&a, &b, 400, 993), at(&a, &b, 400, 1022));
        assert!(
            l.0 > 220 && l.1 < 35 && r.0 < 35 && r.1 > 220,
            "{name}: {l:?} {r:?}"
        );
        let m = at(&a, &b, 400, 1008);
        assert!((m.0 - m.1).abs() < 40, "{name}: middle {m:?}");
        assert!(worst_step <= 24, "{name}: column step {worst_step}");
        eprintln!("{name}: overlap sum within ±{worst_sum}, largest column step {worst_step}");
    }
}

#[test]
fn tiled_2x1_without_blend_doubles_the_dose() {
    let dir = tempdir("geom-noblend");
    let src = stdout(&run_in(&dir, &["profile", "show", "tiled-2x1"]));
    std::fs::write(
        dir.join("none.toml"),
        src.replace("curve = \"raised-cosine\"", "curve = \"none\""),
    )
    .unwrap();
    let (a, b) = tiled_plate(&dir, "none.toml", "n.dmdjob");
    // Linear response: gray is irradiance, so the overlap gets twice the light.
    for r in PLATE_ROWS {
        for c in 992..1024 {
            assert_eq!(at(&a, &b, r, c), (255, 255));
        }
    }
}

#[test]
fn distortion_command_reports_fit_reach_and_plots() {
    let dir = tempdir("geom-cmd");
    write_table(&dir.join("barrel.csv"), Lens::Radial(-0.05), 0.01, 3);
    let o = run_in(
        &dir,
        &["distortion", "barrel.csv", "--plot", "b.png", "--json"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["report"]["points"], 140);
    assert_eq!(v["report"]["source"], "barrel.csv");
    // Barrel pulls the light inwards: the corners are out of reach.
    let reach = v["reachable_fraction"].as_f64().unwrap();
    assert!((0.8..0.99).contains(&reach), "{reach}");
    let img = image::open(dir.join("b.png")).unwrap().to_rgb8();
    assert!(img.width() > 520 && img.height() > 392);
    assert!(title_text_pixels(&img) > 100, "no title text");
    // Unreachable corners: gray cells, and the swatch saying what they mean.
    let gray = img.pixels().filter(|p| p.0 == [200, 200, 200]).count();
    assert!(gray > 500, "{gray} gray pixels");
    // The same picture as JPEG; another extension is refused before any work.
    let o = run_in(&dir, &["distortion", "barrel.csv", "--plot", "b.jpg", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let jpg = image::open(dir.join("b.jpg")).unwrap();
    assert_eq!(jpg.width(), img.width());
    let o = run_in(&dir, &["distortion", "barrel.csv", "--plot", "b.gif"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("b.gif: cannot write pictures as .gif; use .png, .jpg or .jpeg"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.join("b.gif").exists());
    let o = run_in(&dir, &["distortion", "barrel.csv"]);
    assert!(stdout(&o).contains("reachable: "), "{}", stdout(&o));
    let o = run_in(&dir, &["distortion", "nope.csv"]);
    assert_eq!(o.status.code(), Some(2));
    let o = run_in(
        &dir,
        &["distortion", "barrel.csv", "--profile", "tiled-2x1"],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("profiles with 2 projectors cannot use one"),
        "{}",
        stderr(&o)
    );
}

/// A `[projector.calibration]` block: field P = scale·(1 + gx·u + gy·v) over the projector's
/// own 65 × 48.75 mm (u, v in cm), response a table through (pixel value, S) points.
fn calibration_block(gx: f64, gy: f64, points: &str) -> String {
    format!(
        "[projector.calibration]
source = \"test\"
units = \"relative\"
zone_mm = 5.0
[projector.calibration.field]
origin_mm = [0.0, 0.0]
length_unit_mm = 10.0
scale = 1.0
coefficients = {{ c = 1.0, x = {gx}, y = {gy} }}
area_mm = [0.0, 0.0, 65.0, 48.75]
extrapolate_mm = 0.0
[projector.calibration.response]
kind = \"table\"
interpolation = \"pchip\"
points = [{points}]
"
    )
}

/// A gamma-like (≈ 2.2) response.
const GAMMA: &str = "[0.0, 0.0], [64.0, 0.048], [128.0, 0.22], [192.0, 0.535], [255.0, 1.0]";

/// `tiled-2x1` with a calibration block after each projector.
fn calibrated_tiled(dir: &Path, name: &str, blocks: [String; 2]) -> dmdsl::profile::Profile {
    let src = stdout(&run_in(dir, &["profile", "show", "tiled-2x1"]));
    let mut parts: Vec<String> = src.split("\n[[projector]]\n").map(String::from).collect();
    assert_eq!(parts.len(), 3);
    // parts[1] is p0's keys; parts[2] p1's keys and everything after: insert the block
    // right after each projector's keys (before the next table header).
    let cut = parts[2].find("\n[").unwrap() + 1;
    parts[2].insert_str(cut, &blocks[1]);
    parts[1].push_str(&blocks[0]);
    let text = parts.join("\n[[projector]]\n");
    std::fs::write(dir.join(name), &text).unwrap();
    dmdsl::profile::Profile::resolve(dir.join(name).to_str().unwrap()).unwrap()
}

#[test]
fn every_tiled_layer_lit_outside_a_projectors_calibrated_area_counts() {
    // A prism 40 layers tall reaching 3 mm above p0's calibrated area: without the cure
    // correction each layer but a block's first shows the masks of the layer below, and
    // is counted all the same.
    let dir = tempdir("geom-outside");
    let block = calibration_block(0.03, -0.02, GAMMA).replace(
        "area_mm = [0.0, 0.0, 65.0, 48.75]\nextrapolate_mm = 0.0",
        "area_mm = [0.0, 0.0, 65.0, 45.0]\nextrapolate_mm = 5.0",
    );
    calibrated_tiled(&dir, "o.toml", [block.clone(), block]);
    let tall = box_tris([10.0, 40.0, 0.0], [50.0, 48.0, 2.0]);
    write_stl(&dir.join("tall.stl"), &tall);
    let args = [
        "slice",
        "tall.stl",
        "--keep-position",
        "--profile",
        "o.toml",
    ];
    let args = [
        &args[..],
        &["--cure-correction", "off", "-q", "-o", "t.dmdjob"],
    ]
    .concat();
    let job = slice(&dir, &args);
    assert_eq!(job["layers"].as_array().unwrap().len(), 40);
    let notes = warnings_of(&job, "optics.outside-calibrated-area");
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert_eq!(notes[0]["fields"]["projector"], "p0");
    assert_eq!(notes[0]["fields"]["layers"], 40, "{}", notes[0]);
}

#[test]
fn tiled_blend_goes_through_a_nonlinear_response() {
    let dir = tempdir("geom-gamma");
    let blk = calibration_block(0.0, 0.0, GAMMA);
    let prof = calibrated_tiled(&dir, "g.toml", [blk.clone(), blk]);
    let s = prof.projector[0]
        .calibration
        .as_ref()
        .unwrap()
        .response
        .curve();
    write_stl(
        &dir.join("plate.stl"),
        &box_tris([50.0, 10.0, 0.0], [80.0, 30.0, 0.12]),
    );
    let job = slice(
        &dir,
        &[
            "slice",
            "plate.stl",
            "--keep-position",
            "--profile",
            "g.toml",
            "--compensation",
            "off",
            "-q",
            "-o",
            "g.dmdjob",
        ],
    );
    assert_eq!(job["settings"]["compensation"], "off");
    let m = &job["layers"][0]["masks"];
    let a = read_gray(&dir.join("g.dmdjob").join(m[0]["file"].as_str().unwrap())).2;
    let b = read_gray(&dir.join("g.dmdjob").join(m[1]["file"].as_str().unwrap())).2;
    let (mut worst, mut gray_sum_max) = (0.0f64, 0);
    for r in PLATE_ROWS {
        for c in 992..1024 {
            let (va, vb) = at(&a, &b, r, c);
            let e = s.eval(va as f64) + s.eval(vb as f64);
            worst = worst.max((e - 1.0).abs());
            gray_sum_max = gray_sum_max.max(va + vb);
        }
        assert_eq!(at(&a, &b, r, 900), (255, 0));
        assert_eq!(at(&a, &b, r, 1100), (0, 255));
    }
    // The shares sum to one in irradiance (within the 8-bit steps of the response) ...
    assert!(worst < 0.02, "irradiance sum off by {worst}");
    // ... which takes gray sums far above 255 ...
    assert!(gray_sum_max > 330, "{gray_sum_max}");
    // ... while halving the gray (scheme B of Zhang et al. 2024) would give under half the dose.
    let half = 2.0 * s.eval(128.0);
    assert!(half < 0.5, "{half}");
}

#[test]
fn tiled_compensation_per_projector_flattens_across_the_seam() {
    let dir = tempdir("geom-comp");
    // Two projectors with different fields and responses.
    let prof = calibrated_tiled(
        &dir,
        "c.toml",
        [
            calibration_block(0.03, -0.02, GAMMA),
            calibration_block(-0.04, 0.03, "[0.0, 0.0], [255.0, 1.3]"),
        ],
    );
    let cals: Vec<_> = prof
        .projector
        .iter()
        .map(|p| p.calibration.clone().unwrap())
        .collect();
    write_stl(
        &dir.join("plate.stl"),
        &box_tris([50.0, 10.0, 0.0], [80.0, 30.0, 0.12]),
    );
    for (mode, tol) in [("pixel", 0.012), ("zone", 0.03)] {
        let out = format!("{mode}.dmdjob");
        let job = slice(
            &dir,
            &[
                "slice",
                "plate.stl",
                "--keep-position",
                "--profile",
                "c.toml",
                "--compensation",
                mode,
                "--dither",
                "off",
                "-q",
                "-o",
                &out,
            ],
        );
        assert_eq!(job["settings"]["compensation"], mode);
        let po = job["projector_optics"].as_array().unwrap();
        assert_eq!(po.len(), 2);
        let target = po[0]["target_irradiance"].as_f64().unwrap();
        assert_eq!(po[1]["target_irradiance"].as_f64().unwrap(), target);
        for (k, o) in po.iter().enumerate() {
            assert_eq!(o["projector"], k);
            let f = o["gray_map"].as_str().unwrap();
            assert_eq!(f, format!("optics/p{k}-gray-map.png"));
            assert_eq!(read_gray(&dir.join(&out).join(f)).0, 1024);
        }
        let m = &job["layers"][0]["masks"];
        let a = read_gray(&dir.join(&out).join(m[0]["file"].as_str().unwrap())).2;
        let b = read_gray(&dir.join(&out).join(m[1]["file"].as_str().unwrap())).2;
        // Predicted irradiance P_k(x, y)·S_k(g_k), summed over the projectors, in units of
        // the common target: flat over the plate, seam included.
        let curves: Vec<_> = cals.iter().map(|c| c.response.curve()).collect();
        let mut worst = 0.0f64;
        for r in PLATE_ROWS.step_by(7) {
            let y = H - (r as f64 + 0.5) * P;
            for c in PLATE_COLS {
                let (va, vb) = at(&a, &b, r, c);
                let mut e = 0.0;
                if c < 1024 {
                    let x = (c as f64 + 0.5) * P;
                    e += cals[0].field.eval(x, y) * curves[0].eval(va as f64);
                }
                if c >= 992 {
                    let x = (c as f64 - 992.0 + 0.5) * P;
                    e += cals[1].field.eval(x, y) * curves[1].eval(vb as f64);
                }
                worst = worst.max((e / target - 1.0).abs());
            }
        }
        eprintln!("{mode}: largest deviation from the common target {worst:.4}");
        assert!(worst < tol, "{mode}: off by {worst}");
    }
    // Compensation needs every projector calibrated.
    let o = run_in(
        &dir,
        &[
            "slice",
            "plate.stl",
            "--profile",
            "tiled-2x1",
            "--compensation",
            "zone",
            "-o",
            "x.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("projector p0 of tiled profile \"tiled-2x1\" has no light calibration"),
        "{}",
        stderr(&o)
    );
}

/// Dark (text) pixels in the top 40 rows of a picture: its title.
fn title_text_pixels(img: &image::RgbImage) -> usize {
    img.enumerate_pixels()
        .filter(|(_, y, p)| *y < 40 && p.0.iter().all(|&c| c < 110))
        .count()
}

#[test]
fn distortion_colour_bar_covers_the_reported_correction() {
    // fixtures/lens_table.csv: the 1 mm cells' largest correction (1.79 mm) is below the
    // table's (2.106 mm, the fit report's); the bar runs to the larger.
    let mut profile = dmdsl::profile::Profile::resolve(dmdsl::profile::DEFAULT_PROFILE).unwrap();
    let c = dmdsl::geometry::distortion::for_job(
        &dmdsl::geometry::distortion::DistortionChoice::Table(fixture("lens_table.csv")),
        &mut profile,
    )
    .unwrap()
    .unwrap();
    let report = c.report();
    let hm = c.plot();
    let [lo, hi] = hm.scale();
    let finite: Vec<f64> = hm
        .values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let cells_max = finite.iter().copied().fold(0.0, f64::max);
    let cells_min = finite.iter().copied().fold(f64::INFINITY, f64::min);
    assert!(cells_max < report.max_correction_mm, "{cells_max}");
    // The bar ends at the largest correction (the report writes it to 6 significant
    // digits).
    assert!(
        hi >= report.max_correction_mm && hi - report.max_correction_mm < 1e-5,
        "{hi} vs {}",
        report.max_correction_mm
    );
    assert!(lo <= cells_min && lo == 0.0);
    assert!(hm.quantity.contains("(mm)") && hm.x_label.contains("(mm)"));
    // In the picture, the colour bar's top is the colour of the largest correction and no
    // cell reaches it (the cells stop at 1.79 of 2.106 mm).
    let img = hm.render().to_rgb();
    let top = dmdsl::plot::colormap(1.0);
    let cell_of_max = hm.color_of(cells_max);
    assert!(img.pixels().any(|p| p.0 == top), "no colour bar top");
    assert!(img.pixels().any(|p| p.0 == cell_of_max));
    assert_ne!(cell_of_max, top);
    assert!(title_text_pixels(&img) > 100, "no title text");
}
