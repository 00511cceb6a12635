//! Stage-by-stage cost of the slicing pipeline on a real model (no test harness).
//!
//! `cargo bench --bench pipeline -- [MODEL.stl] [LAYER_HEIGHT]`
//! (default: fixtures/bunny00.stl at 0.05 mm). Prints the median of 5 runs per stage,
//! per layer, single-threaded, so the numbers compare across machines and commits.
//! For reference it also encodes the same masks with the `image` crate's PNG encoder
//! (fast compression, no filter: its quickest setting), which dmdsl's own encoder replaces.

#[path = "../examples/common/mod.rs"]
mod common;

use common::median;
use dmdsl::job::encode_png;
use dmdsl::profile::Profile;
use dmdsl::raster::{Rasterizer, Scratch};
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, ImageEncoder};
use std::time::Instant;

fn main() {
    let args = common::args();
    let model = common::path_arg(&args, 0, "bunny00.stl");
    let h: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(0.05);
    let profile = Profile::default_profile();
    let field = profile.field();

    let t = Instant::now();
    let (mesh, n) = common::placed(&model, &profile, h);
    let load_s = t.elapsed().as_secs_f64();

    let mut slice_t = Vec::new();
    let mut sections = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        sections = dmdsl::slice::slice(&mesh, h, n).0;
        slice_t.push(t.elapsed().as_secs_f64());
    }
    let raster = Rasterizer::new(field);
    let mut scratch = Scratch::default();
    let (mut cov_t, mut png_t, mut sha_t) = (Vec::new(), Vec::new(), Vec::new());
    let mut crate_t = Vec::new();
    let (mut png_bytes, mut crate_bytes) = (0usize, 0usize);
    for _ in 0..5 {
        let (mut c, mut p, mut s, mut k) = (0.0, 0.0, 0.0, 0.0);
        (png_bytes, crate_bytes) = (0, 0);
        for sec in &sections {
            let t = Instant::now();
            let m = raster.coverage(&sec.contours, &mut scratch);
            c += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let png = encode_png(&m);
            p += t.elapsed().as_secs_f64();
            let t = Instant::now();
            std::hint::black_box(dmdsl::bundle::sha256_hex(&png));
            s += t.elapsed().as_secs_f64();
            png_bytes += png.len();
            let t = Instant::now();
            let mut out = Vec::with_capacity(png.len());
            PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::NoFilter)
                .write_image(&m.data, m.width, m.height, ExtendedColorType::L8)
                .expect("image encodes");
            k += t.elapsed().as_secs_f64();
            crate_bytes += out.len();
        }
        cov_t.push(c);
        png_t.push(p);
        sha_t.push(s);
        crate_t.push(k);
    }
    let per = |v: Vec<f64>| median(v) / n as f64 * 1e3;
    println!(
        "model {} ({} triangles), {n} layers of {h} mm",
        model.display(),
        mesh.triangles.len()
    );
    println!("load and place      {:8.2} ms total", load_s * 1e3);
    println!("slice (all layers)  {:8.2} ms total", median(slice_t) * 1e3);
    println!("coverage raster     {:8.3} ms/layer", per(cov_t));
    println!(
        "png encode          {:8.3} ms/layer ({} bytes/layer)",
        per(png_t),
        png_bytes / n
    );
    println!(
        "png encode, image   {:8.3} ms/layer ({} bytes/layer; fast, no filter)",
        per(crate_t),
        crate_bytes / n
    );
    println!("sha256              {:8.3} ms/layer", per(sha_t));
}
