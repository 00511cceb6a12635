//! `dmdsl slice` as a user runs it: real and project-made models in, bundles out.

use crate::common::*;
use serde_json::Value;
use std::path::Path;

const P: f64 = 65.0 / 1024.0;

fn slice_ok(dir: &Path, args: &[&str]) -> Value {
    // These tests check geometry (coverage masks: the exact sections); light
    // compensation and the cure correction, on by default with the built-in profile, are
    // tested in tests/it/calibrate.rs and tests/it/cure.rs.
    let mut args = args.to_vec();
    if args.first() == Some(&"slice") {
        args.extend(["--compensation", "off", "--cure-correction", "off"]);
    }
    let args = &args[..];
    let o = run_in(dir, args);
    assert!(o.status.success(), "dmdsl {args:?} failed: {}", stderr(&o));
    let out = args
        .iter()
        .position(|a| *a == "-o")
        .map(|i| dir.join(args[i + 1]))
        .expect("tests pass -o");
    serde_json::from_slice(&std::fs::read(out.join("job.json")).unwrap()).unwrap()
}

/// Slices fixture `name` with `--keep-position` (plus `extra`) into `dir/out`.
fn slice_kept(dir: &Path, name: &str, out: &str, extra: &[&str]) -> Value {
    let f = fixture(name);
    let mut args = vec![
        "slice",
        f.to_str().unwrap(),
        "--keep-position",
        "-q",
        "-o",
        out,
    ];
    args.extend_from_slice(extra);
    slice_ok(dir, &args)
}

fn mask(bundle: &Path, job: &Value, layer: usize) -> Vec<u8> {
    let f = job["layers"][layer]["masks"][0]["file"].as_str().unwrap();
    let (w, h, px) = read_gray(&bundle.join(f));
    assert_eq!((w, h), (1024, 768));
    px
}

/// Expected mask of pixel-aligned rectangles: (col0, col1, row_from_bottom0, row_from_bottom1).
fn rect_mask(rects: &[(usize, usize, usize, usize)]) -> Vec<u8> {
    let mut m = vec![0u8; 1024 * 768];
    for &(c0, c1, b0, b1) in rects {
        for b in b0..b1 {
            let row = 767 - b;
            m[row * 1024 + c0..row * 1024 + c1].fill(255);
        }
    }
    m
}

#[test]
fn cube_keep_position_golden_mask_exact() {
    let dir = tempdir("cube");
    let job = slice_kept(&dir, "cube10.stl", "c.dmdjob", &[]);
    assert_eq!(job["layers"].as_array().unwrap().len(), 200);
    let want = rect_mask(&[(256, 416, 192, 352)]);
    for layer in [0, 99, 199] {
        assert!(
            mask(&dir.join("c.dmdjob"), &job, layer) == want,
            "layer {layer}"
        );
    }
    let l0 = &job["layers"][0];
    assert_eq!(l0["z_mm"], 0.05);
    assert_eq!(l0["slice_z_mm"], 0.025);
    assert_eq!(l0["mode"], "layered");
    let area = l0["area_mm2"].as_f64().unwrap();
    assert!((area - (160.0 * P).powi(2)).abs() < 1e-6, "{area}");
    assert_eq!(job["source"]["placement"]["mode"], "keep");
    assert_eq!(job["source"]["mesh"]["closed_manifold"], true);
    assert_eq!(job["source"]["mesh"]["format"], "stl-binary");
}

#[test]
fn cube_centered_by_default() {
    let dir = tempdir("cube-center");
    let f = fixture("cube10.stl");
    let job = slice_ok(
        &dir,
        &["slice", f.to_str().unwrap(), "-q", "-o", "c.dmdjob"],
    );
    let m = mask(&dir.join("c.dmdjob"), &job, 0);
    // 160 px wide part centred on 1024 x 768: columns 432..592, rows 304..464.
    assert!(m == rect_mask(&[(432, 592, 304, 464)]));
    assert_eq!(job["source"]["placement"]["mode"], "center");
}

#[test]
fn cylinder_with_hole_ascii() {
    let dir = tempdir("cyl");
    let job = slice_kept(&dir, "cylinder_hole.stl", "c.dmdjob", &[]);
    assert_eq!(job["source"]["mesh"]["format"], "stl-ascii");
    assert_eq!(job["layers"].as_array().unwrap().len(), 100);
    let b = dir.join("c.dmdjob");
    let m = mask(&b, &job, 50);
    // Exact area of the 128-gon annulus.
    let ngon = |r: f64| 0.5 * 128.0 * r * r * (std::f64::consts::TAU / 128.0).sin();
    let exact = ngon(8.0) - ngon(3.0);
    let lit: f64 = m.iter().map(|&v| v as f64 / 255.0).sum::<f64>() * P * P;
    assert!((lit - exact).abs() / exact < 1e-3, "{lit} vs {exact}");
    let area = job["layers"][50]["area_mm2"].as_f64().unwrap();
    assert!((area - exact).abs() / exact < 1e-3);
    // Pixels whose centre is clearly inside the ring are 255, clearly outside 0.
    for row in 0..768 {
        for col in 0..1024 {
            let x = (col as f64 + 0.5) * P - 32.5;
            let y = (767.0 - row as f64 + 0.5) * P - 24.375;
            let r = (x * x + y * y).sqrt();
            let v = m[row * 1024 + col];
            if (3.1..7.9).contains(&r) {
                assert_eq!(v, 255, "({col},{row}) r={r}");
            } else if !(2.9..=8.1).contains(&r) {
                assert_eq!(v, 0, "({col},{row}) r={r}");
            }
        }
    }
    // Golden: the whole layer, byte for byte (regenerate only after reviewing a change).
    let golden = read_gray(&fixture("golden/cylinder_hole_layer50.png")).2;
    assert!(
        m == golden,
        "layer 50 differs from fixtures/golden/cylinder_hole_layer50.png"
    );
}

#[test]
fn overlapping_and_touching_shells_union() {
    let dir = tempdir("overlap");
    let job = slice_kept(&dir, "overlap_shells.stl", "o.dmdjob", &[]);
    let want = rect_mask(&[
        (100, 300, 100, 200),
        (200, 400, 150, 300),
        (400, 500, 150, 300),
    ]);
    let m = mask(&dir.join("o.dmdjob"), &job, 10);
    let diff = m.iter().zip(&want).filter(|(a, b)| a != b).count();
    assert_eq!(diff, 0);
    // The touching boxes share a face's edges, so they form one (non-manifold) shell.
    assert_eq!(job["source"]["mesh"]["shells"], 2);
    assert!(job["source"]["mesh"]["nonmanifold_edges"].as_u64().unwrap() > 0);
}

#[test]
fn vertices_on_planes_and_flat_faces() {
    let dir = tempdir("vop");
    let job = slice_kept(
        &dir,
        "vertex_on_plane.stl",
        "v.dmdjob",
        &["--layer-height", "0.25"],
    );
    let layers = job["layers"].as_array().unwrap();
    assert_eq!(layers.len(), 8);
    let r = 100.0 * P;
    for (i, l) in layers.iter().enumerate() {
        let z = 0.125 + 0.25 * i as f64;
        // Octahedron: square of half-diagonal r·(1 − |z − 1.125|), area 2·s².
        let s = r * (1.0 - (z - 1.125f64).abs());
        let octa = 2.0 * s * s;
        let boxa = (100.0 * P).powi(2); // bottom face on plane 0 counts; thin box's top doesn't
        let area = l["area_mm2"].as_f64().unwrap();
        let exact = octa + boxa;
        assert!(
            (area - exact).abs() < 1e-4 * exact,
            "layer {i}: {area} vs {exact}"
        );
    }
    // The equator layer (z = 1.125, vertices on the plane) is an exact diamond: check a
    // pixel-centre row through it.
    let m = mask(&dir.join("v.dmdjob"), &job, 4);
    let row = 767 - 300;
    let lit: Vec<usize> = (0..1024).filter(|&c| m[row * 1024 + c] >= 128).collect();
    assert_eq!((lit[0], *lit.last().unwrap()), (200, 599));
}

#[test]
fn island_above_a_gap() {
    let dir = tempdir("island");
    let job = slice_kept(&dir, "island.stl", "i.dmdjob", &[]);
    let b = dir.join("i.dmdjob");
    assert_eq!(job["layers"].as_array().unwrap().len(), 100);
    assert!(mask(&b, &job, 10) == rect_mask(&[(200, 300, 200, 300)]));
    // The gap (z 2..3) has empty masks but still layers.
    let gap = mask(&b, &job, 50);
    assert!(gap.iter().all(|&v| v == 0));
    assert_eq!(job["layers"][50]["area_mm2"], 0.0);
    assert!(mask(&b, &job, 70) == rect_mask(&[(250, 450, 250, 350)]));
}

#[test]
fn real_model_bunny_json_summary_and_warnings() {
    let dir = tempdir("bunny");
    let f = fixture("bunny00.stl");
    let o = run_in(
        &dir,
        &[
            "slice",
            f.to_str().unwrap(),
            "--json",
            "--layer-height",
            "0.5",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let v: Value = serde_json::from_str(&stdout(&o)).expect("--json prints JSON on stdout");
    assert_eq!(v["layers"], 78);
    assert!(v["bundle"].as_str().unwrap().ends_with("bunny00.dmdjob"));
    assert_eq!(v["mesh"]["triangles"], 75408);
    assert_eq!(v["mesh"]["closed_manifold"], true);
    assert!(v["timings"]["total_s"].as_f64().unwrap() > 0.0);
    assert!(dir.join("bunny00.dmdjob/job.json").is_file());
    // The manifest's masks exist and their hashes match.
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("bunny00.dmdjob/job.json")).unwrap())
            .unwrap();
    for l in job["layers"].as_array().unwrap() {
        let m = &l["masks"][0];
        let bytes =
            std::fs::read(dir.join("bunny00.dmdjob").join(m["file"].as_str().unwrap())).unwrap();
        assert_eq!(m["sha256"].as_str().unwrap(), sha256(&bytes));
    }
}

fn sha256(b: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(b)
        .iter()
        .map(|x| format!("{x:02x}"))
        .collect()
}

#[test]
fn byte_identical_whatever_the_thread_count() {
    let dir = tempdir("repro");
    let f = fixture("bunny00.stl");
    let mut bundles = Vec::new();
    for threads in ["1", "2", "3"] {
        let out = format!("b{threads}.dmdjob");
        let f = f.to_str().unwrap();
        let args = ["slice", f, "-q", "--layer-height", "1", "-o", &out];
        let o = run_threads(&dir, &args, threads);
        assert!(o.status.success(), "{}", stderr(&o));
        bundles.push(tree(&dir.join(out)));
    }
    assert!(bundles[0] == bundles[1] && bundles[1] == bundles[2]);
}

#[test]
fn broken_mesh_warns_and_strict_fails() {
    let dir = tempdir("broken");
    // A cube with one facet missing and one flipped.
    let mut t = box_tris([10.0, 10.0, 0.0], [20.0, 20.0, 5.0]);
    t.remove(7);
    let f = t[4];
    t[4] = [f[0], f[2], f[1]];
    write_stl(&dir.join("broken.stl"), &t);
    let o = run_in(
        &dir,
        &[
            "slice",
            "broken.stl",
            "-o",
            "b.dmdjob",
            "--layer-height",
            "0.5",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("warning: mesh has 3 open edges"), "{e}");
    assert!(e.contains("backwards edges"), "{e}");
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("b.dmdjob/job.json")).unwrap()).unwrap();
    // Repaired sections are the full 10 x 10 mm square.
    for l in job["layers"].as_array().unwrap() {
        let a = l["area_mm2"].as_f64().unwrap();
        assert!((a - 100.0).abs() < 0.05, "{a}");
    }
    assert!(!job["warnings"].as_array().unwrap().is_empty());
    let o = run_in(
        &dir,
        &["slice", "broken.stl", "-o", "b.dmdjob", "--strict", "-q"],
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(
        dir.join("b.dmdjob/job.json").is_file(),
        "--strict still writes the bundle"
    );
}

#[test]
fn obj_input() {
    let dir = tempdir("obj");
    let obj =
        "v 10 10 0\nv 20 10 0\nv 20 20 0\nv 10 20 0\nv 10 10 5\nv 20 10 5\nv 20 20 5\nv 10 20 5\n\
               f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    std::fs::write(dir.join("cube.obj"), obj).unwrap();
    let job = slice_ok(
        &dir,
        &[
            "slice",
            "cube.obj",
            "-q",
            "-o",
            "c.dmdjob",
            "--layer-height",
            "1",
        ],
    );
    assert_eq!(job["source"]["mesh"]["format"], "obj");
    assert_eq!(job["source"]["mesh"]["closed_manifold"], true);
    assert_eq!(job["layers"].as_array().unwrap().len(), 5);
    let a = job["layers"][2]["area_mm2"].as_f64().unwrap();
    assert!((a - 100.0).abs() < 1e-2, "{a}");
}

#[test]
fn replaces_only_bundles_atomically() {
    let dir = tempdir("replace");
    let f = fixture("cube10.stl");
    let f = f.to_str().unwrap();
    slice_ok(
        &dir,
        &["slice", f, "-q", "-o", "x.dmdjob", "--layer-height", "1"],
    );
    slice_ok(
        &dir,
        &["slice", f, "-q", "-o", "x.dmdjob", "--layer-height", "2"],
    );
    let job: Value =
        serde_json::from_slice(&std::fs::read(dir.join("x.dmdjob/job.json")).unwrap()).unwrap();
    assert_eq!(job["layers"].as_array().unwrap().len(), 5);
    // Old masks are gone: the bundle was replaced whole.
    assert!(!dir.join("x.dmdjob/masks/00009.png").exists());
    // A directory that is not a bundle is never replaced.
    std::fs::create_dir(dir.join("precious")).unwrap();
    std::fs::write(dir.join("precious/notes.txt"), "keep me").unwrap();
    let o = run_in(&dir, &["slice", f, "-q", "-o", "precious"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("precious: exists and is not a dmdsl bundle"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("precious/notes.txt")).unwrap(),
        "keep me"
    );
    // No staging directories are left behind.
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.starts_with('.')), "{names:?}");
}

/// Runs `slice` on a bad input: exit code 2, one line on stderr naming the file and the
/// problem, nothing written.
fn bad_input(name: &str, bytes: Option<&[u8]>, expect: &str) {
    bad_input_with(name, bytes, &[], expect)
}

/// [`bad_input`] with more `slice` arguments.
fn bad_input_with(name: &str, bytes: Option<&[u8]>, args: &[&str], expect: &str) {
    let dir = tempdir(&format!("bad-{name}"));
    if let Some(b) = bytes {
        std::fs::write(dir.join(name), b).unwrap();
    }
    let mut all = vec!["slice", name, "-o", "out.dmdjob"];
    all.extend_from_slice(args);
    let o = run_in(&dir, &all);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{name}: {e}");
    assert_eq!(
        e.trim_end().lines().count(),
        1,
        "{name}: one line expected: {e}"
    );
    assert!(e.contains(name), "{name}: error must name the file: {e}");
    assert!(e.contains(expect), "{name}: expected '{expect}' in: {e}");
    assert!(
        !e.contains('\u{1b}'),
        "{name}: a raw escape character: {e:?}"
    );
    assert!(!e.contains("panicked"));
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let expected_left = usize::from(bytes.is_some());
    assert_eq!(
        left.len(),
        expected_left,
        "{name}: nothing may be written: {left:?}"
    );
}

#[test]
fn bad_inputs_are_one_line_errors_with_exit_2() {
    let tri = box_tris([1.0, 1.0, 0.0], [2.0, 2.0, 1.0]);
    let mut good = Vec::new();
    {
        let d = tempdir("bad-src");
        write_stl(&d.join("g.stl"), &tri);
        good = std::fs::read(d.join("g.stl")).unwrap_or(good);
    }
    bad_input("empty.stl", Some(b""), "file is empty");
    bad_input(
        "trunc.stl",
        Some(&good[..good.len() - 20]),
        "declares 12 triangles",
    );
    let mut big = good.clone();
    big[80..84].copy_from_slice(&5_000_000u32.to_le_bytes());
    bad_input("count.stl", Some(&big), "declares 5000000 triangles");
    let ascii = "solid a\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n";
    bad_input("cut.stl", Some(ascii.as_bytes()), "ends inside a facet");
    let mut nan = good.clone();
    nan[84 + 12..84 + 16].copy_from_slice(&f32::NAN.to_le_bytes());
    bad_input("nan.stl", Some(&nan), "non-finite");
    let mut inf = good.clone();
    inf[84 + 20..84 + 24].copy_from_slice(&f32::INFINITY.to_le_bytes());
    bad_input("inf.stl", Some(&inf), "non-finite");
    let mut zero = vec![0u8; 84];
    zero[..5].copy_from_slice(b"solix");
    bad_input("zero.stl", Some(&zero), "contains no triangles");
    let flat = box_tris([1.0, 1.0, 0.0], [2.0, 2.0, 0.0]);
    let d = tempdir("bad-flat-src");
    write_stl(&d.join("f.stl"), &flat);
    bad_input(
        "flat.stl",
        Some(&std::fs::read(d.join("f.stl")).unwrap()),
        "less than one layer",
    );
    let huge = box_tris([0.0, 0.0, 0.0], [70.0, 10.0, 1.0]);
    write_stl(&d.join("h.stl"), &huge);
    bad_input(
        "huge.stl",
        Some(&std::fs::read(d.join("h.stl")).unwrap()),
        "part is 70.000 x 10.000 mm but the build field is 65.000 x 48.750 mm",
    );
    bad_input(
        "bad.obj",
        Some(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n"),
        "line 4: face vertex \"7\" is not an index of the 3 vertices",
    );
    let mut rnd = Vec::with_capacity(4096);
    let mut x: u64 = 0x9e3779b97f4a7c15;
    for _ in 0..4096 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        rnd.push((x >> 24) as u8);
    }
    bad_input("random.stl", Some(&rnd), "not an STL");
    bad_input("missing.stl", None, "No such file");
    let o = run_in(&tempdir("bad-missing2"), &["slice", "missing.stl"]);
    assert_eq!(
        stderr(&o).matches("No such file").count(),
        1,
        "{}",
        stderr(&o)
    );
    // An open surface (one wall of a box): no layer has a closed section.
    let wall: Vec<_> = box_tris([0.0; 3], [10.0, 10.0, 10.0])
        .into_iter()
        .filter(|t| t.iter().all(|v| v[1] == 0.0))
        .collect();
    assert_eq!(wall.len(), 2);
    write_stl(&d.join("w.stl"), &wall);
    bad_input(
        "wall.stl",
        Some(&std::fs::read(d.join("w.stl")).unwrap()),
        "nothing to print: none of the",
    );
    // Terminal escape sequences quoted from the file are shown escaped.
    let esc = "solid \u{1b}[31mx\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex \u{1b}[2J 0 1\n";
    bad_input("esc.stl", Some(esc.as_bytes()), "found '\\u{1b}[2J'");
    // A FIFO is refused instead of blocking until a writer comes.
    #[cfg(unix)]
    {
        let dir = tempdir("bad-fifo");
        let made = std::process::Command::new("mkfifo")
            .arg(dir.join("pipe.stl"))
            .status()
            .unwrap();
        assert!(made.success());
        let o = run_in(&dir, &["slice", "pipe.stl", "-o", "out.dmdjob"]);
        assert_eq!(o.status.code(), Some(2));
        assert!(
            stderr(&o).contains("pipe.stl: is not a regular file"),
            "{}",
            stderr(&o)
        );
        assert!(!dir.join("out.dmdjob").exists());
    }
    // A directory.
    let dir = tempdir("bad-dir");
    std::fs::create_dir(dir.join("adir.stl")).unwrap();
    let o = run_in(&dir, &["slice", "adir.stl", "-o", "out.dmdjob"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("adir.stl: is a directory"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn far_vertices_and_tiny_layers_are_refused_before_slicing() {
    // One vertex of a 10 mm box moved far up: the part is taller than the stage travels
    // (before, the layer count saturated and wrapped, or tried to allocate terabytes).
    let d = tempdir("far-src");
    for (i, z) in [1e20f32, 1e12, 1e6].into_iter().enumerate() {
        let mut tris = box_tris([0.0; 3], [10.0, 10.0, 10.0]);
        for t in tris.iter_mut() {
            for v in t.iter_mut() {
                if *v == [10.0, 10.0, 10.0] {
                    v[2] = z;
                }
            }
        }
        let name = format!("far{i}.stl");
        write_stl(&d.join(&name), &tris);
        bad_input_with(
            &name,
            Some(&std::fs::read(d.join(&name)).unwrap()),
            &["--layer-height", "1"],
            "but the stage travels only to stage.travel_max_mm",
        );
    }
    let name = "box.stl";
    write_stl(&d.join(name), &box_tris([0.0; 3], [10.0, 10.0, 10.0]));
    let bytes = std::fs::read(d.join(name)).unwrap();
    for h in ["1e-300", "1e-12", "1e-6"] {
        // The stage cannot make such steps: the error names the profile.
        let o = run_in(&d, &["slice", name, "--layer-height", h, "-o", "t.dmdjob"]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{h}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{h}: {e}");
        assert!(
            e.contains("profile xu2010-topdown") && e.contains("coarser than the layer height"),
            "{h}: {e}"
        );
        assert!(!d.join("t.dmdjob").exists());
    }
    // On a stage with the finest resolution a profile may give, the layer count is the
    // limit.
    let o = run_in(&d, &["profile", "show", "xu2010-topdown"]);
    let fine = stdout(&o).replace("steps_per_mm = 800.0", "steps_per_mm = 10000000.0");
    std::fs::write(d.join("fine.toml"), fine).unwrap();
    let p = d.join("fine.toml");
    bad_input_with(
        name,
        Some(&bytes),
        &["--layer-height", "1e-7", "-p", p.to_str().unwrap()],
        "layers needs more than 1000000 layers",
    );
}

#[test]
fn usage_errors_exit_2() {
    let dir = tempdir("usage");
    let f = fixture("cube10.stl");
    let f = f.to_str().unwrap();
    for (args, expect) in [
        (
            vec!["slice", f, "--layer-height", "0"],
            "--layer-height must be a number > 0",
        ),
        (
            vec!["slice", f, "--layer-height", "nan"],
            "--layer-height must be a number > 0",
        ),
        (
            vec!["slice", f, "--profile", "nope"],
            "profile nope: no built-in profile",
        ),
        (vec!["slice"], "required"),
        (vec!["frobnicate"], "unrecognized subcommand"),
    ] {
        let o = run_in(&dir, &args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn profile_show_round_trips_and_bad_profile_is_clear() {
    let dir = tempdir("profile");
    let o = run_in(&dir, &["profile", "show", "xu2010-topdown"]);
    assert!(o.status.success());
    let text = stdout(&o);
    assert!(text.contains("pixel_mm = 0.0634765625"));
    std::fs::write(dir.join("my.toml"), &text).unwrap();
    let f = fixture("cube10.stl");
    let job = slice_ok(
        &dir,
        &[
            "slice",
            f.to_str().unwrap(),
            "--profile",
            "my.toml",
            "-q",
            "-o",
            "a.dmdjob",
            "--layer-height",
            "2",
        ],
    );
    assert_eq!(job["machine"]["name"], "xu2010-topdown");
    std::fs::write(
        dir.join("bad.toml"),
        text.replace("mirror_x = false", "mirror_x = false\nmirorr_y = 1"),
    )
    .unwrap();
    let o = run_in(
        &dir,
        &[
            "slice",
            f.to_str().unwrap(),
            "--profile",
            "bad.toml",
            "-o",
            "b.dmdjob",
        ],
    );
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("bad.toml") && e.contains("unknown field `mirorr_y`"),
        "{e}"
    );
    assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    assert!(!dir.join("b.dmdjob").exists());
}

#[test]
fn implausible_machine_values_are_refused_naming_the_key() {
    let dir = tempdir("profile-ranges");
    let f = fixture("cube10.stl");
    let show = |name: &str| stdout(&run_in(&dir, &["profile", "show", name]));
    let (one, tiled) = (show("xu2010-topdown"), show("tiled-2x1"));
    let cases = [
        // µm typed for mm.
        (
            &one,
            "pixel_mm = 0.0634765625",
            "pixel_mm = 63.4765625",
            "pixel_mm = 63.4765625 is not a pixel size",
        ),
        (
            &one,
            "offset_px = [0, 0]",
            "offset_px = [4294967295, 0]",
            "offset_px[0] = 4294967295",
        ),
        (
            &tiled,
            "offset_px = [992, 0]",
            "offset_px = [4000000000, 0]",
            "offset_px[0] = 4000000000",
        ),
        (
            &one,
            "zone_mm = 5.0",
            "zone_mm = 1e-308",
            "zone_mm = 1e-308 is smaller than a pixel",
        ),
        (
            &one,
            "zone_mm = 5.0",
            "zone_mm = 0.0005",
            "zone_mm = 0.0005 is smaller than a pixel",
        ),
    ];
    for (i, (text, from, to, expect)) in cases.into_iter().enumerate() {
        assert!(text.contains(from), "{from}");
        let name = format!("p{i}.toml");
        std::fs::write(dir.join(&name), text.replacen(from, to, 1)).unwrap();
        let out = format!("o{i}.dmdjob");
        let o = run_in(
            &dir,
            &["slice", f.to_str().unwrap(), "-p", &name, "-o", &out],
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{to}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{to}: {e}");
        assert!(e.contains(&name) && e.contains(expect), "{to}: {e}");
        assert!(!dir.join(&out).exists());
    }
    // Quantities out of their unit's range, and a stage too coarse for the layers, are
    // refused before anything is sliced (they planned moves to `inf` mm, times that
    // serialized as `null`, or a job its own executor rejects).
    for (from, to, expect) in [
        (
            "layer_s = 8.0",
            "layer_s = 1e308",
            "exposure.layer_s = 1e308 is not a duration",
        ),
        (
            "return_speed_mm_s = 1.0",
            "return_speed_mm_s = 1e-308",
            "recoat.return_speed_mm_s = 1e-308 is not a speed",
        ),
        (
            "steps_per_mm = 800.0",
            "steps_per_mm = 1e308",
            "stage.steps_per_mm = 1e308 is not a stage resolution",
        ),
        (
            "steps_per_mm = 800.0",
            "steps_per_mm = 0.008",
            "gives steps of 125 mm, coarser than the layer height",
        ),
    ] {
        assert!(one.contains(from), "{from}");
        std::fs::write(dir.join("u.toml"), one.replacen(from, to, 1)).unwrap();
        let o = run_in(
            &dir,
            &[
                "slice",
                f.to_str().unwrap(),
                "-p",
                "u.toml",
                "-o",
                "u.dmdjob",
            ],
        );
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{to}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{to}: {e}");
        assert!(e.contains("u.toml") && e.contains(expect), "{to}: {e}");
        assert!(!dir.join("u.dmdjob").exists());
    }
}

#[test]
fn mirror_flags_flip_the_image() {
    let dir = tempdir("mirror");
    let o = run_in(&dir, &["profile", "show", "xu2010-topdown"]);
    let text = stdout(&o).replace("mirror_x = false", "mirror_x = true");
    std::fs::write(dir.join("mx.toml"), text).unwrap();
    let f = fixture("cube10.stl");
    let job = slice_ok(
        &dir,
        &[
            "slice",
            f.to_str().unwrap(),
            "--keep-position",
            "--profile",
            "mx.toml",
            "-q",
            "-o",
            "m.dmdjob",
            "--layer-height",
            "5",
        ],
    );
    let m = mask(&dir.join("m.dmdjob"), &job, 0);
    assert!(m == rect_mask(&[(1024 - 416, 1024 - 256, 192, 352)]));
}

#[test]
fn ctrl_c_leaves_nothing_behind() {
    let dir = tempdir("ctrlc");
    let f = fixture("bunny00.stl");
    let child = std::process::Command::new(bin())
        .args([
            "slice",
            f.to_str().unwrap(),
            "--layer-height",
            "0.002",
            "-o",
            "x.dmdjob",
        ])
        .current_dir(&dir)
        .stderr(std::process::Stdio::piped())
        .stoppable()
        .spawn()
        .unwrap();
    // Wait until the job is writing masks into its staging directory, then interrupt it.
    let staging = || {
        std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .any(|e| e.file_name().to_string_lossy().starts_with(".x.dmdjob.tmp"))
    };
    let t = std::time::Instant::now();
    while !staging() {
        assert!(t.elapsed().as_secs() < 60, "no staging directory appeared");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    signal(&child, "INT");
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    assert!(stderr(&out).contains("interrupted; nothing was written"));
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn closed_stdout_ends_quietly() {
    // `dmdsl slice … --json | head -c 1`: the reader is gone before the summary is printed.
    // The process must not panic; it ends by SIGPIPE like other command-line tools (or,
    // should the print win the race, with success), and the bundle is complete either way.
    let dir = tempdir("sigpipe");
    let mut child = std::process::Command::new(bin())
        .args([
            "slice",
            &fixture("cube10.stl").to_string_lossy(),
            "--json",
            "-o",
        ])
        .arg(dir.join("c.dmdjob"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run dmdsl");
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        assert!(
            out.status.success() || out.status.signal() == Some(13),
            "{:?}: {err}",
            out.status
        );
    }
    assert!(dir.join("c.dmdjob/job.json").is_file());
}

#[cfg(target_os = "linux")]
#[test]
fn large_fields_keep_memory_to_the_lit_box_tiled_and_per_pixel() {
    // A 10 mm box on two tiled 2048 x 4096 px projectors, and on a 4096 x 4096 px one with
    // per-pixel compensation. Writing every projector pixel and a blend factor for each
    // (tiled), or P, E*/P, level and gray for every field pixel (pixel mode), peaked at
    // about 135 and 190 MB; what follows the lit box stays far below.
    let dir = tempdir("large-fields");
    let cube = fixture("cube10.stl");
    let cube = cube.to_str().unwrap();
    let tiled = [
        "--profile",
        "tiled-2x1",
        "--set",
        "projector.0.width_px=2048",
        "--set",
        "projector.0.height_px=4096",
        "--set",
        "projector.1.width_px=2048",
        "--set",
        "projector.1.height_px=4096",
        "--set",
        "projector.1.offset_px=[2016,0]",
    ];
    let pixel = [
        "--set",
        "projector.0.width_px=4096",
        "--set",
        "projector.0.height_px=4096",
        "--compensation",
        "pixel",
    ];
    for (what, extra, limit) in [
        ("tiled", &tiled[..], 80 << 20),
        ("pixel", &pixel[..], 100 << 20),
    ] {
        let out = format!("{what}.dmdjob.zip");
        let mut args = vec!["slice", cube, "--layer-height", "2", "-q", "-o", &out];
        args.extend_from_slice(extra);
        let (o, code, peak) = run_limited(&dir, &args, None, None);
        assert_eq!(code, Some(0), "{what}: {}", stderr(&o));
        assert!(
            peak > 1 << 20,
            "{what}: the program's memory was read: {peak} bytes"
        );
        assert!(peak < limit, "{what}: peak {peak} bytes");
    }
}
