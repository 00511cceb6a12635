//! Exact coverage (dmdsl's rasterizer) vs tiny-skia on real sections: accuracy and speed.
//!
//! `cargo bench --bench raster -- [MODEL.stl ...]` (default: fixtures/bunny00.stl).
//! For every layer (0.05 mm) it rasterizes the section three ways — dmdsl's exact area
//! coverage, tiny-skia anti-aliased, tiny-skia aliased — and reports the total lit area
//! against the polygons' exact area, how many pixels each puts on the other side of the
//! 50 % level than the exact coverage does, and the time per layer.

#[path = "../examples/common/mod.rs"]
mod common;

use dmdsl::profile::Profile;
use dmdsl::raster::{Rasterizer, Scratch};
use dmdsl::slice::{signed_area, Contour};
use std::path::PathBuf;
use std::time::Instant;

fn tiny_skia_mask(contours: &[Contour], aa: bool, pixel: f64, h_px: u32) -> Vec<u8> {
    let mut pb = tiny_skia::PathBuilder::new();
    for c in contours {
        for (i, p) in c.iter().enumerate() {
            let (x, y) = ((p[0] / pixel) as f32, (h_px as f64 - p[1] / pixel) as f32);
            if i == 0 {
                pb.move_to(x, y);
            } else {
                pb.line_to(x, y);
            }
        }
        pb.close();
    }
    let mut m = tiny_skia::Mask::new(1024, h_px).unwrap();
    if let Some(path) = pb.finish() {
        m.fill_path(
            &path,
            tiny_skia::FillRule::Winding,
            aa,
            tiny_skia::Transform::identity(),
        );
    }
    m.data().to_vec()
}

fn main() {
    let mut models: Vec<PathBuf> = common::args().into_iter().map(PathBuf::from).collect();
    if models.is_empty() {
        models.push(common::fixture("bunny00.stl"));
    }
    let profile = Profile::default_profile();
    let field = profile.field();
    let px2 = field.pixel_mm * field.pixel_mm;
    println!("| model | method | area error | pixels across 50 % vs exact (% of lit) | ms/layer |");
    println!("|---|---|---:|---:|---:|");
    for model in models {
        let (mesh, n) = common::placed(&model, &profile, 0.05);
        let sections = dmdsl::slice::slice(&mesh, 0.05, n).0;
        let exact_area: f64 = sections
            .iter()
            .flat_map(|s| &s.contours)
            .map(signed_area)
            .sum();
        let raster = Rasterizer::new(field);
        let mut scratch = Scratch::default();
        let name = model.file_name().unwrap().to_string_lossy().into_owned();
        // Per method: summed coverage (px), pixels across 50 % vs exact, seconds.
        let mut stats = [(0.0f64, 0usize, 0.0f64); 3];
        let mut lit = 0usize;
        for s in &sections {
            let t0 = Instant::now();
            let exact = raster.coverage(&s.contours, &mut scratch);
            stats[0].2 += t0.elapsed().as_secs_f64();
            lit += exact.data.iter().filter(|&&v| v >= 128).count();
            stats[0].0 += exact.lit_pixels();
            for (k, aa) in [(1, true), (2, false)] {
                let t0 = Instant::now();
                let ts = tiny_skia_mask(&s.contours, aa, field.pixel_mm, field.height_px);
                stats[k].2 += t0.elapsed().as_secs_f64();
                stats[k].0 += ts.iter().map(|&v| v as f64).sum::<f64>() / 255.0;
                stats[k].1 += ts
                    .iter()
                    .zip(&exact.data)
                    .filter(|(x, y)| (**x >= 128) != (**y >= 128))
                    .count();
            }
            scratch.recycle(exact);
        }
        for (k, label) in [
            "dmdsl exact coverage",
            "tiny-skia anti-aliased",
            "tiny-skia aliased",
        ]
        .iter()
        .enumerate()
        {
            println!(
                "| {name} | {label} | {:+.4} % | {:.4} | {:.3} |",
                100.0 * (stats[k].0 * px2 / exact_area - 1.0),
                100.0 * stats[k].1 as f64 / lit as f64,
                stats[k].2 / n as f64 * 1e3
            );
        }
    }
}
