//! `dmdsl inspect` as a user runs it: the summary against the manifest, and the contact
//! sheet, chart and preview checked for what they show.

use crate::common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// A base plate 10..40 × 10..20 mm, 1 mm thick, with a tower 30..40 × 10..20 mm on its
/// right end up to 3 mm, sliced at 0.5 mm with the file's coordinates (6 layers: 0–1
/// the plate, 2–5 the tower) into `<dir>/step.dmdjob`.
fn stepped(name: &str, extra: &[&str]) -> (TempDir, PathBuf) {
    stepped_to(name, 3.0, extra)
}

/// [`stepped`] with the tower's top at `top` mm.
fn stepped_to(name: &str, top: f32, extra: &[&str]) -> (TempDir, PathBuf) {
    let dir = tempdir(&format!("inspect-{name}"));
    let mut tris = box_tris([10.0, 10.0, 0.0], [40.0, 20.0, 1.0]);
    tris.extend(box_tris([30.0, 10.0, 1.0], [40.0, 20.0, top]));
    write_stl(&dir.join("step.stl"), &tris);
    let mut args = vec![
        "slice",
        "step.stl",
        "--layer-height",
        "0.5",
        "--keep-position",
        "-q",
    ];
    args.extend_from_slice(extra);
    let o = run_in(&dir, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let b = dir.join("step.dmdjob");
    (dir, b)
}

fn job(b: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(b.join("job.json")).unwrap()).unwrap()
}

fn ok(o: &std::process::Output) {
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(o), stderr(o));
}

fn rgb(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Dark pixels (text) in rows `y0..y1`.
fn dark_pixels(img: &image::RgbImage, y0: u32, y1: u32) -> usize {
    (y0..y1.min(img.height()))
        .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c < 110))
        .count()
}

#[test]
fn summary_numbers_are_the_manifests() {
    let (dir, b) = stepped("summary", &[]);
    let o = run_in(&dir, &["inspect", "step.dmdjob", "--json"]);
    ok(&o);
    let s: Value = serde_json::from_slice(&o.stdout).unwrap();
    let j = job(&b);
    assert_eq!(s["schema_version"], 1);
    assert_eq!(s["ok"], true);
    assert_eq!(s["layers"], 6);
    let layers = j["layers"].as_array().unwrap();
    assert_eq!(layers.len(), 6);
    for key in ["height_mm", "print_time_s", "exposure_s", "resin_volume_ml"] {
        assert_eq!(s[key], j["totals"][key], "{key}");
    }
    assert_eq!(s["source"], "step.stl");
    assert_eq!(s["profile"], j["machine"]["name"]);
    // Warnings counted by code.
    let mut by_code = std::collections::BTreeMap::<String, u64>::new();
    for w in j["warnings"].as_array().unwrap() {
        *by_code
            .entry(w["code"].as_str().unwrap().to_string())
            .or_default() += 1;
    }
    assert_eq!(s["warnings"], j["warnings"].as_array().unwrap().len());
    assert_eq!(
        s["warnings_by_code"],
        serde_json::to_value(&by_code).unwrap()
    );
    // Each extreme is the largest value of its figure and the first layer with it.
    for (key, field) in [
        ("area_mm2", "area_mm2"),
        ("exposure_s", "exposure_s"),
        ("max_fill_distance_mm", "max_fill_distance_mm"),
        ("islands", "islands"),
        ("time_s", "time_s"),
    ] {
        let values: Vec<f64> = layers.iter().map(|l| l[field].as_f64().unwrap()).collect();
        let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let first = values.iter().position(|&v| v == max).unwrap();
        let e = &s["extremes"][key];
        assert_eq!(e["value"].as_f64().unwrap(), max, "{key}");
        assert_eq!(e["layer"], first, "{key}");
    }
    // The plate is the largest section: 30 × 10 mm on layers 0 and 1.
    let area = s["extremes"]["area_mm2"]["value"].as_f64().unwrap();
    assert!((area - 300.0).abs() < 1.0, "{area}");
    assert_eq!(s["extremes"]["area_mm2"]["layer"], 0);

    // The same for people.
    let o = run_in(&dir, &["inspect", "step.dmdjob"]);
    ok(&o);
    let out = stdout(&o);
    assert!(
        out.starts_with("step.dmdjob: 6 layers of 0.5 mm, 3.00 mm tall; sliced from step.stl"),
        "{out}"
    );
    assert!(out.contains("largest area"), "{out}");
    // Islands are the regions on nothing in the layer below, not all regions.
    assert!(out.contains("most islands on nothing "), "{out}");
    assert!(out.contains("estimated print time"), "{out}");
    // The default profile's zone compensation, and what it looks like in a mask.
    assert_eq!(s["compensation"], "zone");
    assert_eq!(s["zone_mm"], j["optics"]["zone_mm"]);
    assert!(
        out.contains("light compensation: zone: each 5 mm zone has its own gray, so a mask shows faint squares"),
        "{out}"
    );
    let (off, _) = stepped("summary-off", &["--compensation", "off"]);
    let o = run_in(&off, &["inspect", "step.dmdjob"]);
    ok(&o);
    assert!(!stdout(&o).contains("light compensation"), "{}", stdout(&o));
}

#[test]
fn a_job_of_one_layer_says_one_layer() {
    let dir = tempdir("inspect-one");
    write_stl(
        &dir.join("plate.stl"),
        &box_tris([10.0, 10.0, 0.0], [40.0, 20.0, 1.0]),
    );
    ok(&run_in(
        &dir,
        &["slice", "plate.stl", "--layer-height", "1", "-q"],
    ));
    let o = run_in(&dir, &["inspect", "plate.dmdjob"]);
    ok(&o);
    let out = stdout(&o);
    assert!(out.starts_with("plate.dmdjob: 1 layer of 1 mm,"), "{out}");
    let o = run_in(&dir, &["export", "plate.dmdjob", "-o", "plate.sl1"]);
    ok(&o);
    let out = stdout(&o);
    assert!(out.starts_with("plate.sl1: sl1 of 1 layer from"), "{out}");
}

/// The x ranges of the thumbnails in row `y` of a contact sheet: runs of gray pixels (a
/// thumbnail is gray on black; the sheet's background is not a gray).
fn thumbnails_in_row(img: &image::RgbImage, y: u32) -> Vec<(u32, u32)> {
    let gray = |x: u32| {
        let p = img.get_pixel(x, y).0;
        p[0] == p[1] && p[1] == p[2]
    };
    let mut runs = Vec::new();
    let mut x = 0;
    while x < img.width() {
        if gray(x) {
            let start = x;
            while x < img.width() && gray(x) {
                x += 1;
            }
            if x - start > 20 {
                runs.push((start, x));
            }
        }
        x += 1;
    }
    runs
}

#[test]
fn contact_sheet_shows_each_layer_where_it_is() {
    let (dir, _) = stepped("sheet", &["--compensation", "off"]);
    let o = run_in(
        &dir,
        &["inspect", "step.dmdjob", "--contact-sheet", "sheet.png"],
    );
    ok(&o);
    assert!(stdout(&o).contains("picture: sheet.png"), "{}", stdout(&o));
    let img = rgb(&dir.join("sheet.png"));
    assert!(dark_pixels(&img, 0, 40) > 100, "no title text");
    // One row of six thumbnails: find the rows that hold mask black.
    let black_rows: Vec<u32> = (0..img.height())
        .filter(|&y| {
            (0..img.width())
                .filter(|&x| img.get_pixel(x, y).0 == [0, 0, 0])
                .count()
                > 100
        })
        .collect();
    let (top, bottom) = (black_rows[0], *black_rows.last().unwrap());
    let mid = (top + bottom) / 2;
    let thumbs = thumbnails_in_row(&img, mid);
    assert_eq!(thumbs.len(), 6, "{thumbs:?}");
    // The crop is the footprint 10..40 mm plus a 1.2 mm margin: the plate lights 3.7 %
    // to 96.3 % of a thumbnail's width, the tower (layers 2 to 5) 65.4 % to 96.3 %.
    let (lo, hi) = (8.8, 41.2);
    let frac = |x: f64| (x - lo) / (hi - lo);
    for (layer, &(x0, x1)) in thumbs.iter().enumerate() {
        let w = (x1 - x0) as f64;
        let lit: Vec<f64> = (x0..x1)
            .filter(|&x| img.get_pixel(x, mid)[0] > 100)
            .map(|x| (x - x0) as f64 / w)
            .collect();
        let (a, b) = (lit[0], *lit.last().unwrap());
        let want_a = frac(if layer < 2 { 10.0 } else { 30.0 });
        let want_b = frac(40.0);
        assert!(
            (a - want_a).abs() < 0.03 && (b - want_b).abs() < 0.03,
            "layer {layer}: lit {a:.3}..{b:.3}, want {want_a:.3}..{want_b:.3}"
        );
    }
    // Every 2nd layer of 1..5: layers 1, 3, 5.
    let o = run_in(
        &dir,
        &[
            "inspect",
            "step.dmdjob",
            "--contact-sheet",
            "s2.jpg",
            "--every",
            "2",
            "--layers",
            "1..5",
        ],
    );
    ok(&o);
    let img = rgb(&dir.join("s2.jpg"));
    assert!(img.width() > 300 && img.height() > 150);
}

#[test]
fn chart_has_a_panel_per_figure() {
    let (dir, _) = stepped("chart", &[]);
    let o = run_in(&dir, &["inspect", "step.dmdjob", "--chart", "c.png"]);
    ok(&o);
    let img = rgb(&dir.join("c.png"));
    assert_eq!(img.dimensions(), (1200, 1100));
    assert!(dark_pixels(&img, 0, 40) > 100, "no title text");
    // Five panels, each with the series' blue line: count the separate vertical bands of
    // rows holding line pixels.
    let line_rows: Vec<bool> = (0..img.height())
        .map(|y| {
            (0..img.width()).any(|x| {
                let p = img.get_pixel(x, y).0;
                p[2] > 150 && p[0] < 80 && p[1] < 130
            })
        })
        .collect();
    let bands = line_rows.windows(2).filter(|w| !w[0] && w[1]).count() + usize::from(line_rows[0]);
    assert!(bands >= 5, "{bands} bands of line pixels");
    // The y labels name their units.
    let o = run_in(
        &dir,
        &[
            "inspect",
            "step.dmdjob",
            "--chart",
            "c.jpg",
            "--layers",
            "2..4",
        ],
    );
    ok(&o);
    assert_eq!(rgb(&dir.join("c.jpg")).dimensions(), (1200, 1100));
}

#[test]
fn preview_shows_the_tower_on_the_right() {
    let (dir, b) = stepped_to("preview", 6.0, &[]);
    let o = run_in(&dir, &["inspect", "step.dmdjob", "--preview", "p.png"]);
    ok(&o);
    let img = rgb(&dir.join("p.png"));
    let (w, h) = dmdsl::inspect::PREVIEW_SIZE;
    assert_eq!(img.width(), w);
    assert!(img.height() > h && img.height() < h + 100);
    assert!(dark_pixels(&img, 0, 40) > 100, "no title text");

    // The library function: an image of the size asked for, the part in blue, the tower
    // (right end of the plate, 5 mm above it) standing taller on the picture than the
    // plate's left end.
    let bundle = dmdsl::inspect::Bundle::open(&b).unwrap();
    let img = dmdsl::inspect::preview(&bundle.manifest, bundle.files.as_ref(), 400, 300).unwrap();
    assert_eq!(img.dimensions(), (400, 300));
    let part: Vec<(u32, u32)> = img
        .enumerate_pixels()
        .filter(|(_, _, p)| p[2] as i32 > p[0] as i32 + 40)
        .map(|(x, y, _)| (x, y))
        .collect();
    assert!(part.len() > 5000, "{} part pixels", part.len());
    let xs: Vec<u32> = part.iter().map(|p| p.0).collect();
    let (x_min, x_max) = (*xs.iter().min().unwrap(), *xs.iter().max().unwrap());
    let fifth = (x_max - x_min) / 5;
    // The part's height on the picture in columns a..b.
    let extent = |a: u32, b: u32| {
        let ys: Vec<u32> = part
            .iter()
            .filter(|p| p.0 >= a && p.0 < b)
            .map(|p| p.1)
            .collect();
        ys.iter().max().unwrap() - ys.iter().min().unwrap()
    };
    let (left, right) = (
        extent(x_min, x_min + fifth),
        extent(x_max - fifth, x_max + 1),
    );
    assert!(
        right > left + 30,
        "the tower's end ({right} px tall) is not taller than the plate's ({left} px)"
    );
}

#[test]
fn tiled_jobs_show_both_projectors() {
    let dir = tempdir("inspect-tiled");
    // A bar across both projectors of the built-in 127.97 mm wide tiled field.
    write_stl(
        &dir.join("bar.stl"),
        &box_tris([20.0, 20.0, 0.0], [108.0, 30.0, 1.0]),
    );
    let o = run_in(
        &dir,
        &[
            "slice",
            "bar.stl",
            "--profile",
            "tiled-2x1",
            "--keep-position",
            "--layer-height",
            "0.5",
            "--compensation",
            "off",
            "-q",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run_in(&dir, &["inspect", "bar.dmdjob", "--contact-sheet", "s.png"]);
    ok(&o);
    let img = rgb(&dir.join("s.png"));
    let y = (0..img.height())
        .find(|&y| {
            (0..img.width())
                .filter(|&x| img.get_pixel(x, y).0 == [0, 0, 0])
                .count()
                > 100
        })
        .unwrap()
        + 20;
    let thumbs = thumbnails_in_row(&img, y);
    assert_eq!(thumbs.len(), 2, "{thumbs:?}");
    // The bar is lit without a gap where the projectors meet (their overlap adds up).
    let (x0, x1) = thumbs[0];
    let lit: Vec<u32> = (x0..x1).filter(|&x| img.get_pixel(x, y)[0] > 100).collect();
    assert!(!lit.is_empty());
    let span = lit.last().unwrap() - lit[0] + 1;
    assert_eq!(span as usize, lit.len(), "a gap in the bar");
    assert!(span as f64 > 0.85 * (x1 - x0) as f64);
}

#[test]
fn bad_options_are_usage_errors() {
    let (dir, _) = stepped("usage", &[]);
    for (args, needle) in [
        (
            vec!["inspect", "step.dmdjob", "--preview", "p.gif"],
            "p.gif: cannot write pictures as .gif",
        ),
        (
            vec!["inspect", "step.dmdjob", "--every", "2"],
            "--every applies to --contact-sheet",
        ),
        (
            vec!["inspect", "step.dmdjob", "--layers", "1..2"],
            "--layers applies to --contact-sheet and --chart",
        ),
        (
            vec![
                "inspect",
                "step.dmdjob",
                "--chart",
                "c.png",
                "--layers",
                "4..9",
            ],
            "the job has layers 0..5",
        ),
        (vec!["inspect", "nope.dmdjob"], "nope.dmdjob"),
    ] {
        let o = run_in(&dir, &args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(needle), "{args:?}: {e}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
    }
    assert!(!dir.join("p.gif").exists() && !dir.join("c.png").exists());
    // A missing mask is named.
    std::fs::remove_file(dir.join("step.dmdjob/masks/00003.png")).unwrap();
    let o = run_in(&dir, &["inspect", "step.dmdjob", "--preview", "p.png"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("masks/00003.png"), "{}", stderr(&o));
    // The summary needs no mask.
    ok(&run_in(&dir, &["inspect", "step.dmdjob"]));
}
