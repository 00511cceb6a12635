//! The cure correction's cost per layer on real sections: drawing the coverage, solving
//! the drawn edges' moves from the layers above, and moving them.
//!
//! `cargo bench --bench cure -- [MODEL.stl ...]` (default: fixtures/bunny00.stl). For every
//! layer (0.05 mm, default profile, one thread) it draws the coverage (the rasterizer),
//! draws every section's coverage once (as the layers below look at them), solves its edges'
//! moves from its dose and the sections of the layers above (`cure::shift`) and corrects
//! the coverage (`cure::correct_coverage`), and prints the time per layer of each with the
//! moves' range. Whole-job ratios are in docs/BENCHMARKS.md.

#[path = "../examples/common/mod.rs"]
mod common;

use dmdsl::cure::segments::Segments;
use dmdsl::cure::shift::{wall_shifts, Coverage, EdgeProfile, EdgeShifts, LookAhead, LOOK_AHEAD};
use dmdsl::cure::{self, CureModel, Psf};
use dmdsl::profile::Profile;
use dmdsl::raster::{PixelBox, Rasterizer, Scratch};
use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let mut models: Vec<PathBuf> = common::args().into_iter().map(PathBuf::from).collect();
    if models.is_empty() {
        models.push(common::fixture("bunny00.stl"));
    }
    let profile = Profile::default_profile();
    let model = CureModel::from_profile(&profile).expect("the default profile has a PSF");
    let field = profile.field();
    let (p, h) = (field.pixel_mm, field.height_px as f64);
    let edge = EdgeProfile::new(&Psf {
        sigma_px: model.sigma_px,
    });
    let raster = Rasterizer::new(field);
    let ratio = |k: usize| profile.exposure.layer_exposure_s(k) / profile.exposure.layer_s.get();
    println!("| model | layers | coverage ms/layer | sections covered ms/layer | moves solved ms/layer | correction ms/layer | moves px (least, most) |");
    println!("|---|---:|---:|---:|---:|---:|---:|");
    for path in models {
        let (mesh, n) = common::placed(&path, &profile, 0.05);
        let sections = dmdsl::slice::slice(&mesh, 0.05, n).0;
        let mut scratch = Scratch::default();
        // Every section's coverage, as the layers below look at it.
        let t = Instant::now();
        let covered: Vec<Coverage> = sections
            .iter()
            .map(|s| Coverage::draw(&raster, &s.contours, &mut scratch))
            .collect();
        let t_index = t.elapsed().as_secs_f64();
        let (mut t_cov, mut t_solve, mut t_cor) = (0.0, 0.0, 0.0);
        let mut range = (0.0f64, 0.0f64);
        let walls = wall_shifts(&model, &edge, n, ratio);
        for (i, s) in sections.iter().enumerate() {
            let t = Instant::now();
            let mut m = raster.coverage(&s.contours, &mut scratch);
            t_cov += t.elapsed().as_secs_f64();
            let lit = scratch.lit_box();
            let t = Instant::now();
            let segs = Segments::simplified(&s.contours, p, h, 0.01);
            let upper: Vec<&Coverage> = covered[i + 1..].iter().take(LOOK_AHEAD).collect();
            let mut pairs = Vec::new();
            let look = LookAhead::new(&model, (i, n), (ratio, &walls), &upper, &mut pairs);
            let shifts = EdgeShifts::solve(&model, &edge, (&segs, &covered[i]), &look, 4.0);
            t_solve += t.elapsed().as_secs_f64();
            let (lo, hi) = shifts.range();
            range = (range.0.min(lo), range.1.max(hi));
            let t = Instant::now();
            let all = PixelBox {
                r0: 0,
                r1: m.height as usize,
                c0: 0,
                c1: m.width as usize,
            };
            cure::correct_coverage(&mut m, lit, &segs, &shifts, all);
            t_cor += t.elapsed().as_secs_f64();
            scratch.recycle(m);
        }
        let k = sections.len().max(1) as f64 * 1e-3;
        println!(
            "| {} | {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.2}, {:.2} |",
            path.file_name().unwrap().to_string_lossy(),
            sections.len(),
            t_cov / k,
            t_index / k,
            t_solve / k,
            t_cor / k,
            range.0,
            range.1
        );
    }
}
