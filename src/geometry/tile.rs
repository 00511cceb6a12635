//! Multi-projector tiling: one field coverage mask → one gray mask per projector
//! (docs/GEOMETRY.md, "Tiling").
//!
//! Built once per job: per projector a fixed-point factor `F = round(f · 16 · 2¹⁶)` per
//! pixel (`f` its irradiance share from [`blend::weight_maps`], times any gain ≤ 1) and a
//! LUT from irradiance fraction to gray through its response ([`Response::inverse_lut`]).
//! A pixel of coverage `v` becomes `lut[(v · F + 2¹⁵) >> 16]`; mirror flags apply last.
//! With light compensation every projector has its own [`Compensator`], all with one
//! common target irradiance E* (the lowest each would choose alone), so the field is flat
//! across the seam.

use super::blend::{self, Rect, Response, LUT_STEPS};
use crate::bundle::Optics;
use crate::digest::sha256_hex;
use crate::error::{Error, Result};
use crate::optics::{Compensator, GrayMap, JobOptics, Mode, OpticsOptions};
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
    mirror_x: bool,
    mirror_y: bool,
    /// `F` per projector pixel (row-major, unmirrored), or None when every `F` is [`FULL`].
    factor: Option<Vec<u32>>,
    /// Per row, the columns `a..b` outside which every `F` is [`FULL`].
    spans: Vec<(u32, u32)>,
    /// Irradiance fraction (in 1/LUT_STEPS) → gray.
    lut: Vec<u8>,
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
    /// irradiance curve, `gains[k]` an optional extra per-pixel factor ≤ 1 (compensation:
    /// row-major over the projector's pixels, unmirrored).
    pub fn new(
        projectors: &[Projector],
        curve: &BlendCurve,
        responses: &[Response],
        gains: &[Option<Vec<f32>>],
    ) -> Tiler {
        let rects: Vec<Rect> = projectors.iter().map(rect_of).collect();
        let weights = blend::weight_maps(&rects, curve);
        let tiles = projectors
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let gain = gains.get(k).and_then(|g| g.as_ref());
                let w = &weights[k];
                let factor: Vec<u32> = w
                    .iter()
                    .enumerate()
                    .map(|(i, &s)| {
                        let g = gain.map_or(1.0, |g| g[i].clamp(0.0, 1.0));
                        ((s as f64 * g as f64).clamp(0.0, 1.0) * FULL as f64).round() as u32
                    })
                    .collect();
                let all_full = factor.iter().all(|&f| f == FULL);
                let w = p.width_px as usize;
                let spans = factor
                    .chunks(w)
                    .map(|row| {
                        let a = row.iter().position(|&f| f != FULL).unwrap_or(w);
                        let b = row.iter().rposition(|&f| f != FULL).map_or(a, |b| b + 1);
                        (a as u32, b as u32)
                    })
                    .collect();
                Tile {
                    rect: rects[k],
                    mirror_x: p.mirror_x,
                    mirror_y: p.mirror_y,
                    factor: (!all_full).then_some(factor),
                    spans,
                    lut: responses
                        .get(k)
                        .cloned()
                        .unwrap_or_else(Response::linear)
                        .inverse_lut(),
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
        let mut tiler = Tiler::new(ps, &curve, &responses, &vec![None; n]);
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

    /// Projector `k`'s gray mask of a field coverage mask.
    pub fn render(&self, k: usize, field: &Mask) -> Mask {
        if let Some(o) = self.optics.get(k) {
            return self.render_compensated(k, o, field);
        }
        let t = &self.tiles[k];
        let (w, h) = t.rect.size();
        let fw = field.width as usize;
        let mut out = Mask::zeros(w as u32, h as u32);
        let lut = &t.lut[..];
        debug_assert_eq!(lut.len(), LUT_STEPS + 1);
        let black = lut[0];
        // Gray of a pixel with full share at each coverage level.
        let full: Vec<u8> = (0..=255usize).map(|v| lut[v * 16]).collect();
        let identity = full.iter().enumerate().all(|(v, &g)| g as usize == v);
        for r in 0..h {
            let sr = if t.mirror_y { h - 1 - r } else { r };
            let row0 = (t.rect.y0 as usize + r) * fw + t.rect.x0 as usize;
            let src = &field.data[row0..row0 + w];
            let dst = &mut out.data[sr * w..(sr + 1) * w];
            // Full share: a copy (linear response) or one look-up per pixel.
            if identity {
                dst.copy_from_slice(src);
            } else {
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = full[v as usize];
                }
            }
            // Shared or compensated pixels: coverage × F through the response LUT.
            if let Some(f) = &t.factor {
                let (a, b) = (t.spans[r].0 as usize, t.spans[r].1 as usize);
                let fr = &f[r * w + a..r * w + b];
                for ((d, &v), &f) in dst[a..b].iter_mut().zip(&src[a..b]).zip(fr) {
                    *d = if v == 0 {
                        black
                    } else {
                        lut[((v as u32 * f + 0x8000) >> 16) as usize]
                    };
                }
            }
            if t.mirror_x {
                dst.reverse();
            }
        }
        out
    }

    /// Compensated path: crop, scale by the share (8-bit), compensate, mirror.
    fn render_compensated(&self, k: usize, o: &JobOptics, field: &Mask) -> Mask {
        let t = &self.tiles[k];
        let (w, h) = t.rect.size();
        let fw = field.width as usize;
        let mut out = Mask::zeros(w as u32, h as u32);
        for r in 0..h {
            let row0 = (t.rect.y0 as usize + r) * fw + t.rect.x0 as usize;
            let dst = &mut out.data[r * w..(r + 1) * w];
            dst.copy_from_slice(&field.data[row0..row0 + w]);
            if let Some(f) = &t.factor {
                let (a, b) = (t.spans[r].0 as usize, t.spans[r].1 as usize);
                for (d, &f) in dst[a..b].iter_mut().zip(&f[r * w + a..r * w + b]) {
                    *d = ((*d as u32 * f + (FULL >> 1)) / FULL) as u8;
                }
            }
        }
        o.compensator.apply(&mut out);
        if t.mirror_y {
            for r in 0..h / 2 {
                let (top, bottom) = out.data.split_at_mut((h - 1 - r) * w);
                top[r * w..(r + 1) * w].swap_with_slice(&mut bottom[..w]);
            }
        }
        if t.mirror_x {
            out.data.chunks_exact_mut(w).for_each(|row| row.reverse());
        }
        out
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
        (t.render(0, &field), t.render(1, &field))
    }

    #[test]
    fn full_plate_sums_to_255_across_the_seam() {
        let ps = two(64, 16);
        let lin = [Response::linear(), Response::linear()];
        let t = Tiler::new(&ps, &BlendCurve::RaisedCosine, &lin, &[None, None]);
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
        assert_eq!(t.render(0, &field).get(10, 1), 128);
    }

    #[test]
    fn nonlinear_response_gray_gives_the_irradiance_share() {
        let ps = two(64, 16);
        let g = Response::gamma(2.2).unwrap();
        let t = Tiler::new(
            &ps,
            &BlendCurve::Smoothstep,
            &[g.clone(), g.clone()],
            &[None, None],
        );
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
    fn mirror_and_gain() {
        let mut ps = two(8, 0);
        ps[1].mirror_x = true;
        ps[1].offset_px = [8, 0];
        let gain = vec![0.5f32; 32];
        let lin = [Response::linear(), Response::linear()];
        let t = Tiler::new(&ps, &BlendCurve::RaisedCosine, &lin, &[Some(gain), None]);
        let mut field = Mask::zeros(16, 4);
        for c in 0..16 {
            field.data[c] = (c * 10) as u8;
        }
        let a = t.render(0, &field);
        let b = t.render(1, &field);
        assert_eq!(a.get(4, 0), 20); // 40 × 0.5
        assert_eq!(b.get(0, 0), 150); // mirrored: field column 15
        assert_eq!(b.get(7, 0), 80);
    }
}
