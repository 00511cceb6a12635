//! The per-layer apply path: a layer's coverage mask becomes compensated grays, either in
//! place on a finished mask ([`Compensator::apply`], [`Compensator::apply_in`]) or while
//! the rasterizer writes the mask (the [`crate::raster::CoverageMap`] impl); both give
//! the same bytes. Error diffusion lives in [`super::dither`].

use super::{map_words, Compensator, Dither, Mask, Mode};
use crate::png::PixelBox;

impl Compensator {
    /// Rewrites a coverage mask of the field (values = coverage × 255) into compensated grays.
    #[cfg(any(test, feature = "internals"))]
    pub fn apply(&self, m: &mut Mask) {
        self.apply_in(m, PixelBox::whole(self.w, self.h));
    }

    /// [`apply`](Self::apply) for a mask known to be zero outside `lit_box` (e.g.
    /// [`crate::raster::Scratch::lit_box`]): one pass over the box, eight pixels at a time
    /// ([`map_words`]): full coverage takes the gray map, other coverage the zone's table
    /// for the row (zone mode) or a search from the full-coverage level (pixel mode).
    ///
    /// Returns, for a layer that reaches outside the calibrated area (it is then counted
    /// in [`layers_outside`](Self::layers_outside)), how far, mm.
    pub fn apply_in(&self, m: &mut Mask, lit_box: PixelBox) -> Option<f64> {
        assert_eq!(
            (m.width as usize, m.height as usize),
            (self.w, self.h),
            "mask size differs from the field"
        );
        let w = self.w;
        let (br0, bc0) = (lit_box.r0, lit_box.c0);
        let (br1, bc1) = (lit_box.r1.min(self.h), lit_box.c1.min(w));
        if br0 >= br1 || bc0 >= bc1 {
            return None;
        }
        let outside = self.lit_outside(m, PixelBox::new(br0, br1, bc0, bc1));
        match (self.mode, self.dither) {
            (Mode::Zone, _) => {
                for r in br0..br1 {
                    self.zone_row(&mut m.data[r * w..(r + 1) * w], r, bc0, bc1);
                }
            }
            (Mode::Pixel, Dither::On) => {
                let lit = |r: &usize| m.data[r * w + bc0..r * w + bc1].iter().any(|&v| v != 0);
                let first = (br0..br1).find(lit);
                let last = (br0..br1).rev().find(lit);
                if let (Some(r0), Some(r1)) = (first, last) {
                    self.apply_dither(m, r0, r1 + 1);
                }
            }
            (Mode::Pixel, _) => {
                for r in br0..br1 {
                    self.pixel_row(&mut m.data[r * w..(r + 1) * w], r, bc0, bc1);
                }
            }
            (Mode::Off, _) => {}
        }
        outside.then(|| self.record_outside(m, PixelBox::new(br0, br1, bc0, bc1)))
    }

    /// Whether any nonzero pixel of the box lies outside the calibrated area (only the
    /// part of the box outside it is scanned; usually there is none).
    fn lit_outside(&self, m: &Mask, lit_box: PixelBox) -> bool {
        let (PixelBox { r0, r1, c0, c1 }, cal, w) = (lit_box, self.calibrated, self.w);
        let any = |r: usize, a: usize, b: usize| {
            a < b && m.data[r * w + a..r * w + b].iter().any(|&v| v != 0)
        };
        (r0..r1).any(|r| {
            if r < cal.r0 || r >= cal.r1 {
                any(r, c0, c1)
            } else {
                any(r, c0, c1.min(cal.c0)) || any(r, c0.max(cal.c1), c1)
            }
        })
    }

    /// Zone mode, columns [a, b) of row `r` (`row` is the whole row): full pixels take
    /// the zone's gray for this row, edge pixels go through the zone's table.
    fn zone_row(&self, row: &mut [u8], r: usize, a: usize, b: usize) {
        let tabs = self.zone_tables.row(r, self.zones.cols);
        let cols = &self.zones.of_col[a..b];
        let full = &self.gray_row(r)[a..b];
        map_words(&mut row[a..b], full, |k, v| {
            self.zone_tables.tables[tabs[cols[k] as usize] as usize][v as usize]
        });
    }

    /// Pixel mode without dithering, columns [a, b) of row `r`: full pixels take the
    /// gray map's gray, edge pixels (0 < v < 255) are searched from it with E*/P of the
    /// pixel.
    fn pixel_row(&self, row: &mut [u8], r: usize, a: usize, b: usize) {
        let (lv, t) = (&self.levels, &self.pixel_tables);
        let full = &self.gray_row(r)[a..b];
        map_words(&mut row[a..b], full, |k, v| {
            let target = v as f64 / 255.0 * t.target_over_p(r, a + k) as f64;
            lv.gray[lv.nearest_from(t.level(full[k]), target)]
        });
    }
}

/// One row of a [`Compensator`] as the rasterizer's scan uses it
/// ([`crate::raster::CoverageMap::row`]).
#[derive(Clone, Copy)]
pub struct CompRow<'a> {
    comp: &'a Compensator,
    /// The row of the gray map (full coverage).
    full: &'a [u8],
    /// The row's table index of each zone column.
    tabs: &'a [u32],
}

/// The rasterizer applies zone mode while it writes a layer's mask
/// ([`crate::raster::Rasterizer::render`]), with the values of [`Compensator::apply_in`],
/// and reports layers lit outside the calibrated area as it counts them. Pixel mode is
/// not fused (the finished coverage goes through `apply_in`): its edge pixels evaluate P
/// one by one, and error diffusion reads the neighbours' coverage.
impl crate::raster::CoverageMap for Compensator {
    fn fusable(&self) -> bool {
        self.mode == Mode::Zone
    }

    fn area(&self) -> PixelBox {
        self.calibrated
    }

    fn lit_outside(&self, m: &Mask, lit_box: PixelBox) -> f64 {
        self.record_outside(m, lit_box)
    }

    type Row<'a> = CompRow<'a>;

    #[inline(always)]
    fn row(&self, r: usize) -> CompRow<'_> {
        CompRow {
            comp: self,
            full: self.gray_row(r),
            tabs: self.zone_tables.row(r, self.zones.cols),
        }
    }

    #[inline(always)]
    fn fill(row: CompRow<'_>, dst: &mut [u8], a: usize, b: usize, v: u8) {
        let d = &mut dst[a..b];
        if v == 255 {
            let f = &row.full[a..b];
            if d.len() <= 8 {
                d.iter_mut().zip(f).for_each(|(x, &g)| *x = g);
            } else {
                d.copy_from_slice(f);
            }
        } else {
            // One table per zone (and row): a run inside one zone is one value. The zone
            // of a column never decreases along the row.
            let (comp, tabs) = (row.comp, row.tabs);
            let zones = &comp.zones.of_col[a..b];
            let table = |z: u16| &comp.zone_tables.tables[tabs[z as usize] as usize];
            let (first, last) = (zones[0], zones[zones.len() - 1]);
            if first == last {
                let g = table(first)[v as usize];
                if d.len() == 1 {
                    d[0] = g;
                } else {
                    d.fill(g);
                }
            } else {
                for (x, &z) in d.iter_mut().zip(zones) {
                    *x = table(z)[v as usize];
                }
            }
        }
    }

    fn apply(&self, m: &mut Mask, lit_box: PixelBox) -> Option<f64> {
        self.apply_in(m, lit_box)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{response_s as s, rng, setup, small_setup, MODES};
    use super::*;

    #[test]
    fn edge_pixel_gets_inverse_response_of_its_coverage_not_a_scaled_gray() {
        let (cal, field) = setup();
        let c = Compensator::new(&cal, &field, Mode::Zone, Dither::Off).unwrap();
        let pr = &c.prediction;
        // Zone at columns 20..25 (x 20..25 mm), rows 0..5; its mean P is 1 + 22.5/40.
        let pz = 1.0 + 22.5 / 40.0;
        let mut m = Mask::zeros(40, 30);
        for r in 0..5 {
            for col in 20..25 {
                m.data[r * 40 + col] = if col == 24 { 128 } else { 255 };
            }
        }
        c.apply(&mut m);
        let full = m.data[20];
        let edge = m.data[24];
        // Full coverage: the nearest level to E*/P̄; the edge: nearest to (128/255)·E*/P̄.
        let want = |target: f64| {
            (0..=255u8)
                .filter(|&g| g == 0 || g >= 50)
                .min_by(|&a, &b| (s(a) - target).abs().total_cmp(&(s(b) - target).abs()))
                .unwrap()
        };
        assert_eq!(full, want(pr.target / pz));
        assert_eq!(edge, want(128.0 / 255.0 * pr.target / pz));
        // With S = g², half the irradiance is about 0.71 × the gray, not 0.5 ×.
        let scaled = (full as f64 * 128.0 / 255.0).round() as u8;
        assert!(edge > scaled + 20, "edge {edge}, scaled gray {scaled}");
        assert!((s(edge) / s(full) - 128.0 / 255.0).abs() < 0.02);
        // Uncovered pixels stay off.
        assert_eq!(m.data[19], 0);
    }

    #[test]
    fn compensation_in_the_scan_equals_rasterize_then_apply() {
        // Fixed-seed random star polygons (some overlapping: the nonzero fallback; some
        // reaching above the calibrated area: the unfused path) on a 40 × 30 mm field of
        // 0.2 mm pixels, every mode, dithering and binary/anti-aliased: the mask drawn with
        // the compensation in the scan equals coverage → threshold → `apply_in`, the lit
        // area and lit runs are those of the coverage, and the layers outside are counted
        // alike.
        use crate::raster::{threshold, CoverageMap, LitRuns, Rasterizer, Scratch};
        let (cal, field) = small_setup();
        let raster = Rasterizer::new(field);
        let mut rnd = rng(0x2545_f491_4f6c_dd1d);
        let star = |rnd: &mut dyn FnMut() -> f64| {
            let (cx, cy) = (2.0 + rnd() * 36.0, 2.0 + rnd() * 27.0);
            let n = 3 + (rnd() * 40.0) as usize;
            let rmax = 0.3 + rnd() * 12.0;
            crate::test_support::closed(n, true, |a| {
                let rad = rmax * (0.3 + 0.7 * rnd());
                let p = [cx + rad * a.cos(), cy + rad * a.sin()];
                [p[0].clamp(0.0, 40.0), p[1].clamp(0.0, 30.0)]
            })
        };
        let layers: Vec<Vec<Vec<[f64; 2]>>> = (0..48)
            .map(|case| {
                let first = star(&mut rnd);
                let mut shapes = vec![first.clone()];
                if case % 5 == 0 {
                    // The same shell shifted by 0.3 mm: overlapping shells.
                    shapes.push(first.iter().map(|p| [p[0] + 0.3, p[1]]).collect());
                }
                shapes
            })
            .collect();
        for (mode, dither) in MODES {
            for binary in [false, true] {
                let fused = Compensator::new(&cal, &field, mode, dither).unwrap();
                let reference = Compensator::new(&cal, &field, mode, dither).unwrap();
                let recording = || {
                    let mut s = Scratch::default();
                    s.record_runs = true;
                    s
                };
                let (mut s_fused, mut s_ref) = (recording(), recording());
                let mut in_scan = 0;
                for (case, shapes) in layers.iter().enumerate() {
                    let mut want = raster.coverage(shapes, &mut s_ref);
                    let area = s_ref.lit_pixels(&want);
                    let lit = s_ref.lit_box();
                    let (w, h) = (want.width as usize, want.height as usize);
                    let runs = LitRuns::of_mask(&want, [0, h, 0, w]);
                    if binary {
                        threshold(&mut want);
                    }
                    reference.apply_in(&mut want, lit);
                    let got = raster.render(shapes, &mut s_fused, binary, Some(&fused));
                    let what = format!("{mode:?} {dither:?} binary {binary} case {case}");
                    assert!(got == want, "{what}: masks differ");
                    assert_eq!(s_fused.lit_pixels(&got), area, "{what}: lit area");
                    assert_eq!(s_ref.lit_runs, runs, "{what}: lit runs of the coverage");
                    assert_eq!(s_fused.lit_runs, runs, "{what}: lit runs");
                    in_scan += fused.fusable() as usize;
                    s_fused.recycle(got);
                    s_ref.recycle(want);
                }
                assert_eq!(
                    fused.layers_outside(),
                    reference.layers_outside(),
                    "{mode:?} {dither:?} binary {binary}"
                );
                assert!(fused.layers_outside() > 0);
                assert!(
                    mode == Mode::Pixel || in_scan > 20,
                    "{mode:?} {dither:?}: {in_scan}"
                );
            }
        }
    }
}
