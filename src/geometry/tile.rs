//! Multi-projector tiling: one field coverage mask → one gray mask per projector
//! (docs/GEOMETRY.md, "Tiling", gives the fixed-point factors, the LUT and the rows).
//! Built once per job from the shares of [`blend::shares`] and each projector's
//! [`Response::inverse_lut`]; only a layer's lit box is written, mirror flags apply last.
//! With light compensation every projector has its own [`Compensator`], all with one
//! common target irradiance E* (the lowest each would choose alone), so the field is flat
//! across the seam.

use super::blend::{self, Rect, Response, Shares, LUT_STEPS};
use crate::bundle::Optics;
use crate::digest::sha256_hex;
use crate::error::{Error, Result};
use crate::optics::{Compensator, GrayMap, JobOptics, Mode, OpticsOptions};
use crate::png::PixelBox;
use crate::profile::{BlendCurve, Field, Profile, Projector};
use crate::raster::Mask;
use crate::warning::Warning;

/// What the tiling stage of a compensated job hands back after the last layer.
#[derive(Debug, Default)]
pub struct TiledOptics {
    /// Each projector's gray map, for the bundle.
    pub gray_maps: Vec<GrayMap>,
    /// Each projector's manifest record (`projector_optics`).
    pub records: Vec<Optics>,
    /// Warnings for the job.
    pub warnings: Vec<Warning>,
}

/// Fixed-point factor of a full share (f = 1).
const FULL: u32 = 16 << 16;

/// Per-projector tables of a job.
#[derive(Debug, Clone)]
struct Tile {
    rect: Rect,
    /// The projector at offset zero: how its own mask is mirrored.
    view: Projector,
    /// Per row, the columns `a..b` outside which every `F` is [`FULL`], and their `F`
    /// (unmirrored).
    factor: Shares<u32>,
    /// Irradiance fraction (in 1/LUT_STEPS) → gray.
    lut: Vec<u8>,
    /// The gray of each coverage at full share, or None when that is the coverage itself.
    full: Option<Vec<u8>>,
}

/// Splits field coverage masks into blended, response-corrected projector masks.
#[derive(Debug)]
pub struct Tiler {
    tiles: Vec<Tile>,
    /// Per-projector compensation (empty when compensation is off).
    optics: Vec<JobOptics>,
}

impl Tiler {
    /// Tables for `projectors` blended with `curve`; `responses[k]` is projector k's gray →
    /// irradiance curve.
    pub fn new(projectors: &[Projector], curve: &BlendCurve, responses: &[Response]) -> Tiler {
        let rects: Vec<Rect> = projectors.iter().map(rect_of).collect();
        let tiles = (blend::shares(&rects, curve).into_iter().enumerate())
            .map(|(k, s)| {
                let to_f = |s: f32| (s.clamp(0.0, 1.0) as f64 * FULL as f64).round() as u32;
                let response = responses.get(k).cloned();
                let lut = response.unwrap_or_else(Response::linear).inverse_lut();
                debug_assert_eq!(lut.len(), LUT_STEPS + 1);
                let full: Vec<u8> = (0..=255usize).map(|v| lut[v * 16]).collect();
                let identity = full.iter().enumerate().all(|(v, &g)| g as usize == v);
                Tile {
                    rect: rects[k],
                    view: Projector {
                        offset_px: [0, 0],
                        ..projectors[k].clone()
                    },
                    factor: s.map_trimmed(to_f, FULL),
                    lut,
                    full: (!identity).then_some(full),
                }
            })
            .collect();
        Tiler {
            tiles,
            optics: Vec::new(),
        }
    }

    /// The tiling stage of a job on a profile with several projectors: blend curve from
    /// `[blend]`, each projector's response from its calibration (linear without one), and
    /// per-projector compensation when `opts` (or a calibration, by default zone) asks for
    /// it. Resolves the exposure in `profile` like [`crate::optics::prepare`].
    pub fn for_job(
        profile: &mut Profile,
        opts: &OpticsOptions,
        thickness_mm: f64,
    ) -> Result<Tiler> {
        let ps = &profile.projector;
        let n = ps.len();
        let perr = |msg: String| Error::Profile {
            origin: profile.name.clone(),
            msg,
        };
        for (i, p) in ps.iter().enumerate() {
            if ps[..i].iter().any(|q| q.name == p.name) {
                return Err(perr(format!("two projectors are named {:?}", p.name)));
            }
        }
        let response = |p: &Projector| {
            let Some(c) = &p.calibration else {
                return Ok(Response::linear());
            };
            let lv = c.response.levels();
            let pairs: Vec<(u8, f64)> = lv.gray.iter().copied().zip(lv.s).collect();
            Response::from_levels(&pairs).ok_or_else(|| {
                perr(format!(
                    "projector {} calibration: the response has no usable gray levels",
                    p.name
                ))
            })
        };
        let responses = ps.iter().map(response).collect::<Result<Vec<_>>>()?;
        let curve = profile.blend.unwrap_or_default();
        let mut tiler = Tiler::new(ps, &curve, &responses);
        let mode = opts.resolve_mode(ps.iter().any(|p| p.calibration.is_some()))?;
        if mode == Mode::Off {
            return Ok(tiler);
        }
        let mut cals = Vec::with_capacity(n);
        for p in ps {
            let Some(c) = &p.calibration else {
                return Err(Error::Usage(format!(
                    "--compensation {}: projector {} of tiled profile {:?} has no light calibration; every projector needs one (give --calibration {}=FILE) or use --compensation off",
                    mode.as_str(),
                    p.name,
                    profile.name,
                    p.name
                )));
            };
            if c.units != ps[0].calibration.as_ref().map_or(c.units, |c0| c0.units) {
                return Err(perr(
                    "the projectors' calibrations are in different units (relative and mW/cm2)"
                        .into(),
                ));
            }
            cals.push(c.clone());
        }
        let local = |p: &Projector| Field {
            width_px: p.width_px,
            height_px: p.height_px,
            pixel_mm: p.pixel_mm.get(),
        };
        let wrap =
            |p: &Projector, m: String| perr(format!("projector {} calibration: {m}", p.name));
        // One target for all: the lowest each projector would pick alone.
        let mut target = f64::INFINITY;
        for (p, c) in ps.iter().zip(&cals) {
            let alone =
                Compensator::new(c, &local(p), mode, opts.dither).map_err(|m| wrap(p, m))?;
            target = target.min(alone.prediction.target);
        }
        let comps = (ps.iter().zip(&cals))
            .map(|(p, c)| {
                Compensator::with_target(c, &local(p), mode, opts.dither, Some(target))
                    .map_err(|m| wrap(p, m))
            })
            .collect::<Result<Vec<_>>>()?;
        let units = cals[0].units;
        let exposure = crate::optics::exposure::resolve(profile, units, target, thickness_mm);
        tiler.optics = comps
            .into_iter()
            .zip(cals)
            .enumerate()
            .map(|(k, (compensator, calibration))| JobOptics {
                compensator,
                projector: k,
                calibration,
                exposure: exposure.clone(),
            })
            .collect();
        Ok(tiler)
    }

    /// Counts a layer whose projector `k` mask reaches `beyond_mm` outside its calibrated
    /// area, as rendering it did (a layer that shows the masks of another).
    pub fn count_outside(&self, k: usize, beyond_mm: f64) {
        if let Some(o) = self.optics.get(k) {
            o.compensator.count_outside(beyond_mm);
        }
    }

    /// Forgets what the projectors' compensation counted: the job's layers are made again.
    pub fn reset_counts(&self) {
        for o in &self.optics {
            o.compensator.reset_counts();
        }
    }

    /// The compensation mode applied ("off" when none).
    pub fn compensation(&self) -> Mode {
        self.optics
            .first()
            .map_or(Mode::Off, |o| o.compensator.mode())
    }

    /// After all layers: each projector's gray map, the per-projector manifest records and
    /// the job's warnings.
    pub fn finish(&self, profile: &Profile) -> TiledOptics {
        // The gray maps are projector-sized: view them without the field offsets.
        let mut local = profile.clone();
        for p in &mut local.projector {
            p.offset_px = [0, 0];
        }
        let mut out = TiledOptics::default();
        for (k, o) in self.optics.iter().enumerate() {
            let map = o.gray_map(&local);
            let sha = sha256_hex(&map.png);
            let (r, w) = o.finish_with((map.file.clone(), sha));
            out.gray_maps.push(map);
            out.records.push(r);
            for mut w in w {
                // The exposure warnings are the same for every projector.
                if k == 0 || !o.exposure.warnings.contains(&w) {
                    let name = &profile.projector[k].name;
                    w.message = format!("projector {name}: {}", w.message);
                    out.warnings.push(w.with("projector", name.clone()));
                }
            }
        }
        out
    }

    /// Projector `k`'s gray mask of a field coverage mask that is zero outside `lit`,
    /// the box of the projector mask outside which it is zero (or black, when the
    /// response gives a gray above zero for no light: then the whole mask), and how far,
    /// mm, the mask reaches outside the projector's calibrated area, if it does (counted by
    /// its compensation). Only that box is written.
    pub fn render(&self, k: usize, field: &Mask, lit: PixelBox) -> (Mask, PixelBox, Option<f64>) {
        let t = &self.tiles[k];
        let (w, h) = t.rect.size();
        let black = t.lut[0];
        let compensated = self.optics.get(k);
        // The lit box in the projector's own (unmirrored) pixels.
        let (x0, y0) = (t.rect.x0 as usize, t.rect.y0 as usize);
        let cut = |a: usize, b: usize, o: usize, n: usize| {
            let (a, b) = (a.clamp(o, o + n) - o, b.clamp(o, o + n) - o);
            (a, b.max(a))
        };
        let ((r0, r1), (c0, c1)) = (cut(lit.r0, lit.r1, y0, h), cut(lit.c0, lit.c1, x0, w));
        let b = if black == 0 || compensated.is_some() {
            PixelBox::new(r0, r1, c0, c1)
        } else {
            PixelBox::whole(w, h)
        };
        let mut out = Mask::zeros(w as u32, h as u32);
        let fw = field.width as usize;
        for r in b.rows() {
            let row0 = (y0 + r) * fw + x0;
            let src = &field.data[row0 + b.c0..row0 + b.c1];
            let dst = &mut out.data[r * w + b.c0..r * w + b.c1];
            match compensated {
                Some(_) => Self::share_row(t, r, b.c0, src, dst),
                None => Self::gray_row(t, r, b.c0, src, dst),
            }
        }
        let outside = compensated.and_then(|o| o.compensator.apply_in(&mut out, b));
        if !t.view.mirror_x && !t.view.mirror_y {
            return (out, b, outside);
        }
        let (view, b) = crate::raster::projector_view_in(&out, &t.view, b);
        (view.into_owned(), b, outside)
    }

    /// Columns `c0..` of row `r` of tile `t` without compensation: coverage × F through
    /// the response LUT (a copy or one look-up per pixel where the share is full).
    fn gray_row(t: &Tile, r: usize, c0: usize, src: &[u8], dst: &mut [u8]) {
        let lut = &t.lut[..];
        match &t.full {
            None => dst.copy_from_slice(src),
            Some(full) => {
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = full[v as usize];
                }
            }
        }
        let (a, f) = (t.factor.spans[r].0 as usize, t.factor.row(r));
        let (lo, hi) = (a.max(c0), (a + f.len()).min(c0 + src.len()));
        for c in lo..hi.max(lo) {
            let (v, f) = (src[c - c0] as u32, f[c - a]);
            dst[c - c0] = if v == 0 {
                lut[0]
            } else {
                lut[((v * f + 0x8000) >> 16) as usize]
            };
        }
    }

    /// Columns `c0..` of row `r` of tile `t` before compensation: coverage scaled by the
    /// share (8-bit).
    fn share_row(t: &Tile, r: usize, c0: usize, src: &[u8], dst: &mut [u8]) {
        dst.copy_from_slice(src);
        let (a, f) = (t.factor.spans[r].0 as usize, t.factor.row(r));
        let (lo, hi) = (a.max(c0), (a + f.len()).min(c0 + src.len()));
        for c in lo..hi.max(lo) {
            let d = &mut dst[c - c0];
            *d = ((*d as u32 * f[c - a] + (FULL >> 1)) / FULL) as u8;
        }
    }
}

/// A projector's footprint in field pixels.
pub fn rect_of(p: &Projector) -> Rect {
    Rect {
        x0: p.offset_px[0],
        y0: p.offset_px[1],
        x1: p.offset_px[0] + p.width_px,
        y1: p.offset_px[1] + p.height_px,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::Profile;

    fn two(w: u32, overlap: u32) -> Vec<Projector> {
        let mut p = Profile::default_profile().projector[0].clone();
        p.width_px = w;
        p.height_px = 4;
        let mut q = p.clone();
        q.offset_px = [w - overlap, 0];
        vec![p, q]
    }

    /// Both projectors' masks of a full field of `w` columns.
    fn full(t: &Tiler, w: u32) -> (Mask, Mask) {
        let mut field = Mask::zeros(w, 4);
        field.data.fill(255);
        (whole(t, 0, &field), whole(t, 1, &field))
    }

    /// Projector `k`'s mask of the whole of `field`.
    fn whole(t: &Tiler, k: usize, field: &Mask) -> Mask {
        let lit = PixelBox::whole(field.width as usize, field.height as usize);
        t.render(k, field, lit).0
    }

    #[test]
    fn full_plate_sums_to_255_across_the_seam() {
        let ps = two(64, 16);
        let lin = [Response::linear(), Response::linear()];
        let t = Tiler::new(&ps, &BlendCurve::RaisedCosine, &lin);
        let (a, b) = full(&t, 112);
        for c in 0..112u32 {
            let va = if c < 64 { a.get(c, 2) as i32 } else { 0 };
            let vb = if c >= 48 { b.get(c - 48, 2) as i32 } else { 0 };
            assert!((va + vb - 255).abs() <= 1, "col {c}: {va} + {vb}");
        }
        assert_eq!(a.get(0, 0), 255);
        assert_eq!(b.get(63, 0), 255);
        // Coverage scales the shares: a half-covered field gives half the gray.
        let mut field = Mask::zeros(112, 4);
        field.data.fill(128);
        assert_eq!(whole(&t, 0, &field).get(10, 1), 128);
    }

    #[test]
    fn nonlinear_response_gray_gives_the_irradiance_share() {
        let ps = two(64, 16);
        let g = Response::gamma(2.2).unwrap();
        let t = Tiler::new(&ps, &BlendCurve::Smoothstep, &[g.clone(), g.clone()]);
        let (a, b) = full(&t, 112);
        for c in 48..64u32 {
            let e = g.irradiance(a.get(c, 0)).unwrap() + g.irradiance(b.get(c - 48, 0)).unwrap();
            assert!((e - 1.0).abs() < 0.02, "col {c}: {e}");
            // ...and the grays themselves sum to well above 255.
        }
        let mid = a.get(56, 0) as u32 + b.get(8, 0) as u32;
        assert!(mid > 300, "{mid}");
    }

    #[test]
    fn mirror() {
        let mut ps = two(8, 0);
        ps[1].mirror_x = true;
        ps[1].offset_px = [8, 0];
        let lin = [Response::linear(), Response::linear()];
        let t = Tiler::new(&ps, &BlendCurve::RaisedCosine, &lin);
        let mut field = Mask::zeros(16, 4);
        for c in 0..16 {
            field.data[c] = (c * 10) as u8;
        }
        let b = whole(&t, 1, &field);
        assert_eq!(b.get(0, 0), 150); // mirrored: field column 15
        assert_eq!(b.get(7, 0), 80);
    }

    #[test]
    fn a_lit_box_gives_the_whole_render_and_its_box() {
        // A field zero outside a box renders to the same masks when only the box is
        // given, across the seam, mirrored either way, through a nonlinear response; the
        // box handed back holds every nonzero pixel.
        let g = Response::gamma(2.2).unwrap();
        for (mx, my) in [(false, false), (true, false), (false, true), (true, true)] {
            let mut ps = two(64, 16);
            for p in &mut ps {
                (p.height_px, p.mirror_x, p.mirror_y) = (12, mx, my);
            }
            let t = Tiler::new(&ps, &BlendCurve::RaisedCosine, &[g.clone(), g.clone()]);
            let mut field = Mask::zeros(112, 12);
            let lit = PixelBox::new(3, 9, 30, 70);
            for r in lit.rows() {
                for c in lit.cols() {
                    field.data[r * 112 + c] = (r * 37 + c * 11) as u8 | 1;
                }
            }
            for k in 0..2 {
                let (m, b, _) = t.render(k, &field, lit);
                assert!(m == whole(&t, k, &field), "{k} {mx} {my}");
                for (i, &v) in m.data.iter().enumerate() {
                    let (r, c) = (i / 64, i % 64);
                    let inside = b.rows().contains(&r) && b.cols().contains(&c);
                    assert!(v == 0 || inside, "{k} {mx} {my} ({c}, {r}) {b:?}");
                }
            }
        }
    }
}
