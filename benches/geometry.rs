//! Cost of the projector-geometry stages on a real model (no test harness).
//!
//! `cargo bench --bench geometry -- [MODEL.stl] [TABLE.csv]`
//! (default: fixtures/bunny00.stl, fixtures/lens_table.csv, 0.05 mm layers). Single-threaded,
//! median of 5 runs, per layer: the distortion pre-warp of the section contours, the
//! coverage raster of the plain and of the warped contours; then on `tiled-2x1` (model centred
//! on the seam): the coverage raster of the 2016-px field and the blend/LUT split into the two
//! projector masks, against the plain crop of the untiled profile.

#[path = "../examples/common/mod.rs"]
mod common;

use common::median;
use dmdsl::geometry::blend::Response;
use dmdsl::geometry::distortion::{Correction, Table};
use dmdsl::geometry::tile::Tiler;
use dmdsl::profile::Profile;
use dmdsl::raster::{Rasterizer, Scratch};
use std::time::Instant;

fn main() {
    let args = common::args();
    let model = common::path_arg(&args, 0, "bunny00.stl");
    let table = common::path_arg(&args, 1, "lens_table.csv");
    let h = 0.05;
    let profile = Profile::default_profile();
    let field = profile.field();
    let (mesh, n) = common::placed(&model, &profile, h);
    let sections = dmdsl::slice::slice(&mesh, h, n).0;

    let t = Instant::now();
    let tab = Table::read(&table).expect("table reads");
    let corr = Correction::fit(&tab, [field.width_mm(), field.height_mm()], field.pixel_mm)
        .expect("table fits");
    let fit_s = t.elapsed().as_secs_f64();

    let raster = Rasterizer::new(field);
    let mut scratch = Scratch::default();
    let (mut warp_t, mut cov_t, mut covw_t) = (Vec::new(), Vec::new(), Vec::new());
    let (mut v_in, mut v_out) = (0usize, 0usize);
    let mut warped = Vec::new();
    for _ in 0..5 {
        let t = Instant::now();
        warped = sections
            .iter()
            .map(|s| corr.warper().warp(&s.contours).expect("reachable"))
            .collect::<Vec<_>>();
        warp_t.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for s in &sections {
            let m = raster.coverage(&s.contours, &mut scratch);
            scratch.recycle(m);
        }
        cov_t.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for w in &warped {
            let m = raster.coverage(w, &mut scratch);
            scratch.recycle(m);
        }
        covw_t.push(t.elapsed().as_secs_f64());
    }
    for (s, w) in sections.iter().zip(&warped) {
        v_in += s.contours.iter().map(Vec::len).sum::<usize>();
        v_out += w.iter().map(Vec::len).sum::<usize>();
    }
    let per = |v: Vec<f64>| median(v) / n as f64 * 1e3;
    println!(
        "model {} ({} triangles), {n} layers of {h} mm; table {} ({} points)",
        model.display(),
        mesh.triangles.len(),
        table.display(),
        tab.pairs.len()
    );
    println!("{}", corr.report().summary());
    println!("table fit (once)          {:8.2} ms", fit_s * 1e3);
    println!(
        "vertices per layer        {:8.0} -> {:.0} after densification",
        v_in as f64 / n as f64,
        v_out as f64 / n as f64
    );
    println!("distortion pre-warp       {:8.3} ms/layer", per(warp_t));
    println!("coverage raster (plain)   {:8.3} ms/layer", per(cov_t));
    println!("coverage raster (warped)  {:8.3} ms/layer", per(covw_t));

    // Tiling.
    let plain_view = |sections: &[dmdsl::slice::Section], scratch: &mut Scratch| {
        let t = Instant::now();
        for s in sections {
            let m = raster.coverage(&s.contours, scratch);
            std::hint::black_box(dmdsl::raster::projector_view(&m, &profile.projector[0]));
            scratch.recycle(m);
        }
        t.elapsed().as_secs_f64()
    };
    let tiled = Profile::resolve("tiled-2x1").unwrap();
    let tfield = tiled.field();
    let (mesh, _) = common::placed(&model, &tiled, h);
    let tsections = dmdsl::slice::slice(&mesh, h, n).0;
    let t = Instant::now();
    let tiler = Tiler::new(
        &tiled.projector,
        &tiled.blend.unwrap_or_default(),
        &[Response::linear(), Response::linear()],
    );
    let tables_s = t.elapsed().as_secs_f64();
    let traster = Rasterizer::new(tfield);
    let (mut view_t, mut tcov_t, mut split_t) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..5 {
        view_t.push(plain_view(&sections, &mut scratch));
        let (mut c, mut s) = (0.0, 0.0);
        let mut tscratch = Scratch::default();
        for sec in &tsections {
            let t = Instant::now();
            let m = traster.coverage(&sec.contours, &mut tscratch);
            c += t.elapsed().as_secs_f64();
            let t = Instant::now();
            for k in 0..tiled.projector.len() {
                std::hint::black_box(tiler.render(k, &m, tscratch.lit_box()));
            }
            s += t.elapsed().as_secs_f64();
            tscratch.recycle(m);
        }
        tcov_t.push(c);
        split_t.push(s);
    }
    println!("tiled-2x1 tables (once)   {:8.2} ms", tables_s * 1e3);
    println!("untiled raster + view     {:8.3} ms/layer", per(view_t));
    println!("tiled raster (2016 px)    {:8.3} ms/layer", per(tcov_t));
    println!("tiled blend split (2 px.) {:8.3} ms/layer", per(split_t));
}
