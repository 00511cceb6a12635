//! The per-layer analysis alone, as the slicer runs it (an `Analyser` per block of
//! `job::BLOCK` layers, given each layer's lit pixels from the rasterizer; layers equal to
//! the layer below and the islands of a block's first layer resolved afterwards), for
//! instruction counts and result checks.
//!
//! `cargo run --release --example analysis_check -- MODEL > layers.txt`
//!
//! Prints one line per layer: index, max fill distance (mm), islands, bounding box (to
//! compare two builds' results). With `REF=1` in the environment it also reruns every
//! layer's max fill distance at a precision of 0.001 mm and reports on stderr how far the
//! results are below (at most `PRECISION_MM` allowed) and above that reference.
//! Under `RAYON_NUM_THREADS=1 valgrind --tool=callgrind` the inclusive cost of
//! `Analyser::analyse` matches that of `dmdsl slice` within 0.1 %.
mod common;
use dmdsl::plan::analysis;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = std::path::PathBuf::from(&args[1]);
    let (sections, field) = common::default_sections(&path);
    let n = sections.len();
    // The rasterizer as the slicer runs it: it keeps the lit pixels of each mask (drawn
    // from the section without collinear points when it equals the layer below's). Its
    // cost is not the analysis's.
    let raster = dmdsl::raster::Rasterizer::new(field);
    let mut sc = dmdsl::raster::Scratch::default();
    sc.record_runs = true;
    let mut out: Vec<analysis::Analysed> = Vec::with_capacity(n);
    let mut lit: Vec<analysis::LitRuns> = Vec::with_capacity(n);
    for (b, block) in sections.chunks(dmdsl::job::BLOCK).enumerate() {
        let mut a = analysis::Analyser::new();
        for (k, s) in block.iter().enumerate() {
            let i = dmdsl::job::BLOCK * b + k;
            let below = i.checked_sub(1).map(|j| sections[j].contours.as_slice());
            let same = a.equals_below(i, &s.contours, below);
            let m = if same {
                raster.coverage(a.simplified_section(), &mut sc)
            } else {
                raster.coverage(&s.contours, &mut sc)
            };
            sc.recycle(m);
            out.push(a.analyse_or_defer(i, &s.contours, Some(&sc.lit_runs), below));
            lit.push(sc.lit_runs.clone());
        }
    }
    let mut results: Vec<analysis::LayerAnalysis> = Vec::with_capacity(n);
    for (i, r) in out.into_iter().enumerate() {
        let r = r.with_islands(|| analysis::islands_found(&lit[i], &lit[i - 1]));
        results.push(r.resolve(results.last()));
    }
    let mut out = String::new();
    for (i, r) in results.iter().enumerate() {
        out += &format!(
            "{i} {:.6} {} {:?}\n",
            r.max_fill_distance_mm, r.islands, r.bbox_mm
        );
    }
    if std::env::var("REF").is_ok() {
        let (mut worst, mut over) = (0.0f64, 0.0f64);
        for (s, a) in sections.iter().zip(&results) {
            let e = analysis::Edges::new(&s.contours);
            let v = a.max_fill_distance_mm;
            let r = analysis::max_fill_distance_with(&e, 0.001).0;
            worst = worst.max(r - v);
            over = over.max(v - r);
        }
        eprintln!("{}: reference (precision 0.001) minus result: at most {worst:.4} mm; result above reference by at most {over:.4} mm", path.display());
    }
    print!("{out}");
}
