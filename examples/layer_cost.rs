//! The max fill distance of every layer alone, one layer at a time, for per-layer costs
//! and instruction counts of the search.
//!
//! `cargo run --release --example layer_cost -- MODEL [LAYER | FIRST-LAST]`
//!
//! Slices MODEL with the default profile and prints per layer: index, contours, points,
//! the best of 3 runs of `analysis::max_fill_distance` in µs (1 run with `ONE=1` in the
//! environment, or for a single layer), the fill distance (mm) and its centre. Instructions
//! of the search alone, all layers (2026-11-21 figures in docs/BENCHMARKS.md):
//!
//! `ONE=1 valgrind --tool=callgrind --toggle-collect='*max_fill_distance*'
//! target/release/examples/layer_cost MODEL`
mod common;
use dmdsl::plan::analysis;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(&args[1]);
    let (lo, hi) = match args.get(2) {
        None => (0, usize::MAX),
        Some(a) => match a.split_once('-') {
            Some((x, y)) => (x.parse().expect("FIRST"), y.parse().expect("LAST")),
            None => {
                let i = a.parse().expect("LAYER");
                (i, i)
            }
        },
    };
    let reps = if lo == hi || std::env::var("ONE").is_ok() {
        1
    } else {
        3
    };
    let (sections, _) = common::default_sections(&path);
    let n = sections.len();
    let mut total = 0.0;
    for (i, s) in sections
        .iter()
        .enumerate()
        .filter(|(i, _)| (lo..=hi).contains(i))
    {
        let pts: usize = s.contours.iter().map(|c| c.len()).sum();
        let mut best = f64::INFINITY;
        let mut r = (0.0, [0.0, 0.0]);
        for _ in 0..reps {
            let t0 = Instant::now();
            r = analysis::max_fill_distance(&s.contours);
            best = best.min(t0.elapsed().as_secs_f64());
        }
        total += best;
        println!(
            "{i} {} {pts} {:.1} {:.4} {:.3} {:.3}",
            s.contours.len(),
            best * 1e6,
            r.0,
            r.1[0],
            r.1[1]
        );
    }
    eprintln!("layers {n} total {total:.3} s");
}
