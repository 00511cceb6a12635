//! Benchmark of the per-layer analysis against rasterization, single-threaded.
//!
//! `cargo run --release --example plan_bench -- MODEL [LAYER_MM] [REPEATS]`
//!
//! Slices MODEL with the default profile's field, then times (best of REPEATS, default 5)
//! rasterizing every layer (anti-aliased coverage), the max fill distance of every layer
//! and the islands of every layer, and prints their ratios. Compare with the whole `dmdsl
//! slice` run (its `--json` timings include `analysis_cpu_s`). The machine is shared and noisy,
//! hence the best-of-N.

mod common;
use dmdsl::plan::analysis;
use dmdsl::profile::Profile;
use dmdsl::raster::{Rasterizer, Scratch};
use std::time::Instant;

fn best_of<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..n {
        let t0 = Instant::now();
        let v = f();
        best = best.min(t0.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.expect("n > 0"))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(
        args.get(1)
            .expect("usage: plan_bench MODEL [LAYER_MM] [REPEATS]"),
    );
    let p = Profile::default_profile();
    let h: f64 = args
        .get(2)
        .map(|s| s.parse().expect("layer height"))
        .unwrap_or(p.slicing.layer_height_mm.get());
    let reps: usize = args
        .get(3)
        .map(|s| s.parse().expect("repeats"))
        .unwrap_or(5);
    let field = p.field();
    let (mesh, n) = common::placed(&path, &p, h);
    let (t_slice, (sections, _)) = best_of(reps, || dmdsl::slice::slice(&mesh, h, n));
    let r = Rasterizer::new(field);
    let mut sc = Scratch::default();
    let (t_raster, lit) = best_of(reps, || {
        sections
            .iter()
            .map(|s| r.coverage(&s.contours, &mut sc).lit_pixels())
            .sum::<f64>()
    });
    let (t_mfd, sum) = best_of(reps, || {
        sections
            .iter()
            .map(|s| analysis::max_fill_distance(&s.contours).0)
            .sum::<f64>()
    });
    // The lit pixels of every layer, as the slicer's rasterizer keeps them (outside the
    // timings below).
    let lit_runs: Vec<analysis::LitRuns> = {
        let mut sc = Scratch::default();
        sc.record_runs = true;
        sections
            .iter()
            .map(|s| {
                let m = r.coverage(&s.contours, &mut sc);
                sc.recycle(m);
                sc.lit_runs.clone()
            })
            .collect()
    };
    // Islands alone, and the whole analysis as the slicer runs it: an analyser per block
    // of layers, which counts the islands of a block's first layer over the layer below's
    // lit pixels.
    let (t_isl, isl) = best_of(reps, || {
        (0..sections.len())
            .map(|i| match i.checked_sub(1) {
                Some(j) => analysis::islands(&lit_runs[i], &lit_runs[j]),
                None => 0,
            })
            .sum::<u32>()
    });
    let (t_all, _) = best_of(reps, || {
        let mut total = 0.0;
        for (b, block) in sections.chunks(dmdsl::job::BLOCK).enumerate() {
            let mut a = analysis::Analyser::new();
            for (k, s) in block.iter().enumerate() {
                let i = dmdsl::job::BLOCK * b + k;
                let below = i
                    .checked_sub(1)
                    .map(|j| (sections[j].contours.as_slice(), &lit_runs[j]));
                total += a
                    .analyse(i, &s.contours, &lit_runs[i], below)
                    .max_fill_distance_mm;
            }
        }
        total
    });
    let edges: usize = sections
        .iter()
        .map(|s| s.contours.iter().map(|c| c.len()).sum::<usize>())
        .sum();
    let same = (1..sections.len())
        .filter(|&i| sections[i].contours == sections[i - 1].contours)
        .count();
    println!(
        "{}: {n} layers of {h} mm, {:.0} edges/layer, {same} identical to the layer below; best of {reps}, one thread:",
        path.display(),
        edges as f64 / n.max(1) as f64
    );
    println!("  slice             {:8.1} ms", 1e3 * t_slice);
    println!(
        "  raster (coverage) {:8.1} ms  ({:.3} ms/layer, {:.0} lit px)",
        1e3 * t_raster,
        1e3 * t_raster / n as f64,
        lit
    );
    println!(
        "  max fill distance {:8.1} ms  ({:.3} ms/layer, mean {:.3} mm)",
        1e3 * t_mfd,
        1e3 * t_mfd / n as f64,
        sum / n as f64
    );
    println!(
        "  islands           {:8.1} ms  ({:.3} ms/layer, {isl} islands)",
        1e3 * t_isl,
        1e3 * t_isl / n as f64
    );
    println!(
        "  analysis (as run) {:8.1} ms  ({:.3} ms/layer)",
        1e3 * t_all,
        1e3 * t_all / n as f64
    );
    println!("  analysis (as run) / raster = {:.3}", t_all / t_raster);
}
