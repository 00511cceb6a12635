//! Zone mode's tables: one gray per zone for full coverage, from the zone's mean P (the
//! per-zone compensation of Xu et al. 2010, Chinese J. Lasers 37(7)), and per zone a
//! 256-entry table from coverage to gray for the anti-aliased edges. A zone whose one gray
//! misses the target can mix the two grays around it over its rows ([`upper_row`]).

use super::gray_map::GrayMap;
use super::setup::{FieldSurvey, ModePrediction};
use super::spread::{pixel_spread, zone_spread};
use super::zones::ZoneGrid;
use super::{Dither, Levels};

/// Zone mode with `Dither::Auto`: a zone whose nearest gray misses the target by more than
/// this fraction mixes the two grays around the target.
pub const MIX_TOLERANCE: f64 = 0.0075;

/// Whether row `r` of a mixing zone shows the upper of its two grays, for a mix of `k`
/// sixty-fourths: the 6-bit bit-reversal of r mod 64 is below `k` (any 8 consecutive rows
/// hold k/64 of them to within 1/8, any 64 exactly).
#[inline]
pub(super) fn upper_row(r: usize, k: u8) -> bool {
    (((r & 63) as u8).reverse_bits() >> 2) < k
}

/// The full-coverage gray of a zone: `lower` on its rows, except `upper` on
/// `upper_64ths` of every 64 rows ([`upper_row`]; 0 for a zone that does not mix).
#[derive(Debug, Clone, Copy)]
struct GrayMix {
    lower: u8,
    upper: u8,
    upper_64ths: u8,
}

impl GrayMix {
    /// The gray of image row `r`.
    fn on_row(self, r: usize) -> u8 {
        if upper_row(r, self.upper_64ths) {
            self.upper
        } else {
            self.lower
        }
    }
}

/// Zone mode's coverage → gray tables.
#[derive(Debug, Default)]
pub(super) struct ZoneTables {
    /// Per zone, the lower-gray table then (for zones that mix two grays, see
    /// [`upper_row`]) the upper-gray table, which differs only in entry 255.
    pub(super) tables: Vec<[u8; 256]>,
    /// Index into `tables` of each zone column for each image row ([r · zone columns + zc]).
    pub(super) of_row: Vec<u32>,
}

impl ZoneTables {
    /// The table indices of image row `r`, one per zone column.
    #[inline(always)]
    pub(super) fn row(&self, r: usize, zone_cols: usize) -> &[u32] {
        &self.of_row[r * zone_cols..(r + 1) * zone_cols]
    }
}

/// Each zone's coverage → gray table (entry 255 still the nearest gray) and
/// full-coverage gray, with what they predict ([`zone_grays`]).
struct ZoneGrays {
    luts: Vec<[u8; 256]>,
    mix: Vec<GrayMix>,
    /// Predicted full-coverage irradiance of each zone.
    zone_after: Vec<f64>,
    unreachable: u64,
    mixed: u64,
}

/// Zone mode's tables, gray map and prediction for `survey` on the levels `lv`, with the
/// target `forced_target` or chosen here. `None` when no zone has its centre in the
/// calibrated area.
pub(super) fn set_up(
    survey: &FieldSurvey,
    lv: &Levels,
    dither: Dither,
    forced_target: Option<f64>,
) -> Option<(ZoneTables, GrayMap, ModePrediction)> {
    let target = zone_target(survey, lv, dither, forced_target)?;
    let grays = zone_grays(&survey.zone_p, lv, target, dither);
    let zones = &survey.zones;
    let zone_gray: Vec<u8> = grays
        .mix
        .iter()
        .map(|m| {
            if m.upper_64ths >= 32 {
                m.upper
            } else {
                m.lower
            }
        })
        .collect();
    let after_zone = zone_spread(&survey.zone_inside, |z| grays.zone_after[z]);
    // Per-pixel prediction: each row of a zone shows one gray.
    let s_by_gray = s_of_gray(lv);
    let after_pixel = pixel_spread(&survey.sums, &zones.segments, survey.inside, |r, zc| {
        s_by_gray[grays.mix[zones.of_row[r] as usize * zones.cols + zc].on_row(r) as usize]
    });
    let tables = ZoneTables::new(&grays, zones);
    let gray_map = GrayMap::of_zone_tables(&tables, zones);
    let prediction = ModePrediction {
        target,
        zone_gray,
        zone_after: grays.zone_after,
        after_zone_pct: after_zone,
        after_pixel_pct: after_pixel,
        unreachable: grays.unreachable,
        mixed_zones: grays.mixed,
    };
    Some((tables, gray_map, prediction))
}

/// S of each gray on the levels `lv` (0 for grays that are not levels).
fn s_of_gray(lv: &Levels) -> [f64; 256] {
    let mut s_table = [0.0f64; 256];
    for (&g, &sv) in lv.gray.iter().zip(&lv.s) {
        s_table[g as usize] = sv;
    }
    s_table
}

/// The target E*: `forced_target`, or with dithering on the highest irradiance every
/// inside zone can reach, or else [`best_window`] around it. `None` when no zone is
/// inside the calibrated area.
fn zone_target(
    survey: &FieldSurvey,
    lv: &Levels,
    dither: Dither,
    forced_target: Option<f64>,
) -> Option<f64> {
    let (zone_p, zone_inside) = (&survey.zone_p, &survey.zone_inside);
    let pmin = (0..zone_p.len())
        .filter(|&z| zone_inside[z])
        .map(|z| zone_p[z])
        .fold(f64::INFINITY, f64::min);
    if !pmin.is_finite() {
        return None;
    }
    let emax = pmin * lv.s_max();
    Some(match forced_target {
        Some(t) => t,
        None if dither == Dither::On => emax,
        None => best_window(lv, zone_p, zone_inside, emax),
    })
}

/// The zone-mode target (docs/CALIBRATION.md): the centre of the narrowest irradiance window
/// within 3 % of `emax` (the highest every inside zone can reach) that holds one achievable
/// value P̄·S(level) of every inside zone; `emax` if there is none.
fn best_window(lv: &Levels, zone_p: &[f64], inside: &[bool], emax: f64) -> f64 {
    let zones: Vec<usize> = (0..zone_p.len()).filter(|&z| inside[z]).collect();
    let (lo_b, hi_b) = (emax * 0.97, emax * 1.03);
    let mut pairs: Vec<(f64, usize)> = Vec::new();
    for (k, &z) in zones.iter().enumerate() {
        for &s in &lv.s {
            let a = zone_p[z] * s;
            if a >= lo_b && a <= hi_b {
                pairs.push((a, k));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let n = zones.len();
    let mut cnt = vec![0usize; n];
    let (mut have, mut j) = (0usize, 0usize);
    let mut best: Option<(f64, f64)> = None;
    for i in 0..pairs.len() {
        if cnt[pairs[i].1] == 0 {
            have += 1;
        }
        cnt[pairs[i].1] += 1;
        while have == n {
            let (lo, hi) = (pairs[j].0, pairs[i].0);
            let width = (hi - lo) / (hi + lo);
            if best.is_none_or(|b| width < b.0 - 1e-15) {
                best = Some((width, 0.5 * (lo + hi)));
            }
            let k = pairs[j].1;
            cnt[k] -= 1;
            if cnt[k] == 0 {
                have -= 1;
            }
            j += 1;
        }
    }
    best.map_or(emax, |b| b.1)
}

/// Per zone of mean P `zone_p[z]`: the table from coverage v to the level nearest to
/// v/255 · E*/P̄, and the full-coverage gray, which mixes the two levels around E*/P̄
/// when `dither` asks for it.
fn zone_grays(zone_p: &[f64], lv: &Levels, target: f64, dither: Dither) -> ZoneGrays {
    let nz = zone_p.len();
    let s_max = lv.s_max();
    let s_by_gray = s_of_gray(lv);
    let mut mixed = 0u64;
    let mut unreachable = 0;
    let mut luts = vec![[0u8; 256]; nz];
    // v / 255 for each coverage value v.
    let coverage: [f64; 256] = std::array::from_fn(|v| v as f64 / 255.0);
    let mut mix = Vec::with_capacity(nz);
    let mut zone_after = vec![0.0; nz];
    for z in 0..nz {
        let pz = zone_p[z];
        let tz = if pz > 0.0 { target / pz } else { f64::INFINITY };
        if tz > s_max * (1.0 + 1e-9) {
            unreachable += 1;
        }
        if tz >= 0.0 {
            // Targets grow with v: walk the level thresholds upwards (the same levels as
            // `nearest`'s search, in one pass per zone).
            let (mid, lut) = (&lv.mid[..], &mut luts[z]);
            let mut i = 0;
            for v in 1..256 {
                let t = coverage[v] * tz;
                while i < mid.len() && mid[i] <= t {
                    i += 1;
                }
                lut[v] = lv.gray[i];
            }
        } else {
            for (v, out) in luts[z].iter_mut().enumerate().skip(1) {
                *out = lv.gray[lv.nearest(v as f64 / 255.0 * tz)];
            }
        }
        let g = luts[z][255];
        zone_after[z] = pz * s_by_gray[g as usize];
        let mut m = GrayMix {
            lower: g,
            upper: g,
            upper_64ths: 0,
        };
        let miss = (zone_after[z] / target - 1.0).abs();
        let mixing = match dither {
            Dither::On => true,
            Dither::Auto => miss > MIX_TOLERANCE && tz <= s_max,
            Dither::Off => false,
        };
        if mixing {
            mixed += 1;
            // Full coverage: mix the two levels around the target in the fraction that
            // puts the zone mean on it (whole rows, see `upper_row`).
            let i = lv.s.partition_point(|&x| x <= tz).clamp(1, lv.s.len() - 1);
            let (s0, s1) = (lv.s[i - 1], lv.s[i]);
            let f = ((tz - s0) / (s1 - s0)).clamp(0.0, 1.0);
            let k = (f * 64.0).round() as u8;
            m = GrayMix {
                lower: lv.gray[i - 1],
                upper: lv.gray[i],
                upper_64ths: k,
            };
            zone_after[z] = pz * (s0 + (s1 - s0) * k as f64 / 64.0);
        }
        mix.push(m);
    }
    ZoneGrays {
        luts,
        mix,
        zone_after,
        unreachable,
        mixed,
    }
}

impl ZoneTables {
    /// The lower-gray table of every zone, plus an upper-gray one for mixing zones, and
    /// for each image row which of them each zone column uses ([`upper_row`]).
    fn new(grays: &ZoneGrays, zones: &ZoneGrid) -> ZoneTables {
        let (nz, zcols) = (grays.mix.len(), zones.cols);
        let mut tables = Vec::with_capacity(nz + grays.mixed as usize);
        let mut upper_idx = vec![u32::MAX; nz];
        for (l, m) in grays.luts.iter().zip(&grays.mix) {
            let mut l = *l;
            l[255] = m.lower;
            tables.push(l);
        }
        for ((l, m), up) in grays.luts.iter().zip(&grays.mix).zip(&mut upper_idx) {
            if m.upper_64ths > 0 {
                let mut u = *l;
                u[255] = m.upper;
                *up = tables.len() as u32;
                tables.push(u);
            }
        }
        let mut of_row: Vec<u32> = Vec::with_capacity(zones.of_row.len() * zcols);
        for (r, &zr) in zones.of_row.iter().enumerate() {
            let zr = zr as usize * zcols;
            for (z, (m, &u)) in (zr..).zip(
                grays.mix[zr..zr + zcols]
                    .iter()
                    .zip(&upper_idx[zr..zr + zcols]),
            ) {
                of_row.push(if upper_row(r, m.upper_64ths) {
                    u
                } else {
                    z as u32
                });
            }
        }
        ZoneTables { tables, of_row }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_pattern() {
        // k of every 64 consecutive rows show the upper gray, any 8 rows within 1/8.
        for k in 0..=64u8 {
            assert_eq!(
                (0..64).filter(|&r| upper_row(r + 128, k)).count(),
                k as usize
            );
            for s in 0..64 {
                let c = (s..s + 8).filter(|&r| upper_row(r, k)).count() as f64;
                assert!(
                    (c / 8.0 - k as f64 / 64.0).abs() <= 0.125 + 1e-12,
                    "k {k} s {s}"
                );
            }
        }
    }
}
