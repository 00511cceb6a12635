//! The cure model's cost per layer on real sections: drawing the coverage, the XY
//! correction of its edges, and the prediction of the cured edge.
//!
//! `cargo bench --bench cure -- [MODEL.stl ...]` (default: fixtures/bunny00.stl). For every
//! layer (0.05 mm, default profile) it draws the coverage (the rasterizer), corrects it
//! (`cure::correct_coverage`) and predicts its cure (`cure::predict_layer`), one thread,
//! and prints the time per layer of each with the prediction's edge errors. Whole-job
//! ratios (`slice` with and without the correction) are in docs/BENCHMARKS.md.

#[path = "../examples/common/mod.rs"]
mod common;

use dmdsl::cure::{self, CureModel};
use dmdsl::profile::Profile;
use dmdsl::raster::{Rasterizer, Scratch};
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let mut models: Vec<PathBuf> = common::args().into_iter().map(PathBuf::from).collect();
    if models.is_empty() {
        models.push(common::fixture("bunny00.stl"));
    }
    let profile = Profile::default_profile();
    let model = CureModel::from_profile(&profile).expect("the default profile has a PSF");
    let shift = cure::edge_shift_px(&model);
    let raster = Rasterizer::new(profile.field());
    println!("| model | layers | coverage ms/layer | correction ms/layer | prediction ms/layer | edge error mean / p95 px |");
    println!("|---|---:|---:|---:|---:|---:|");
    for path in models {
        let (mesh, n) = common::placed(&path, &profile, 0.05);
        let sections = dmdsl::slice::slice(&mesh, 0.05, n).0;
        let mut scratch = Scratch::default();
        let (mut t_cov, mut t_cor, mut t_pre) = (0.0, 0.0, 0.0);
        let mut hist = cure::predict::Histogram::default();
        let mut sum = (0.0, 0u64);
        for s in &sections {
            let t = Instant::now();
            let mut m = raster.coverage(&s.contours, &mut scratch);
            t_cov += t.elapsed().as_secs_f64();
            let lit = scratch.lit_box();
            let t = Instant::now();
            cure::correct_coverage(&mut m, lit, &s.contours, model.pixel_mm, shift);
            t_cor += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let (c, h) = cure::predict_layer(&model, &m, &s.contours);
            t_pre += t.elapsed().as_secs_f64();
            hist.merge(&h);
            sum.0 += c.abs_mean_px * c.samples as f64;
            sum.1 += c.samples;
            scratch.recycle(m);
        }
        let k = sections.len().max(1) as f64 * 1e-3;
        println!(
            "| {} | {} | {:.3} | {:.3} | {:.3} | {:.3} / {:.2} |",
            path.file_name().unwrap().to_string_lossy(),
            sections.len(),
            t_cov / k,
            t_cor / k,
            t_pre / k,
            sum.0 / sum.1.max(1) as f64,
            hist.quantile(0.95)
        );
    }
}
