//! The regions of a job's layers that rest on nothing below, from the masks alone: a
//! layer's lit pixels (gray ≥ [`LIT_GRAY`] on the field, the projectors' masks put back
//! at their offsets with their mirroring undone and overlaps added up) as runs, their
//! 4-connected components ([`components`], the counter the slicer's islands and the cure
//! check share), and of those the ones that share no lit pixel with the layer below.
//! Layer 0 rests on the platform. `dmdsl run` and `dmdsl inspect --preview` both read
//! them, so they live with the job format.
//!
//! Memory is proportional to the masks' edges, not their pixels: a layer is kept as its
//! runs `[row, first column, end column)`.

use super::machine::Projector;
use std::ops::Range;

/// A run of one row's pixels: `[row, first column, end column)`. Runs are sorted by
/// row, then column, and a row's runs neither overlap nor touch.
pub type Run = [u32; 3];

/// The gray at and above which a field pixel is lit (half of full light).
pub const LIT_GRAY: u8 = 128;

/// Pixels a row's scan tests at once.
const BLOCK: usize = 64;

/// Where a projector's mask lies in the field: its size in pixels, its offset and its
/// mirroring (a projector record's keys).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Placement {
    /// `[width, height]`, px.
    pub size: [u32; 2],
    /// `offset_px`: the field column and row of the mask's first pixel (once mirrored).
    pub offset: [u32; 2],
    /// `[mirror_x, mirror_y]`.
    pub mirror: [bool; 2],
}

impl Placement {
    /// The placement of projector `p`'s masks.
    pub fn of(p: &Projector) -> Placement {
        Placement {
            size: [p.width_px, p.height_px],
            offset: p.offset_px,
            mirror: [p.mirror_x, p.mirror_y],
        }
    }

    /// The field row of mask row `r`.
    fn field_row(&self, r: u32) -> u32 {
        let r = if self.mirror[1] {
            self.size[1] - 1 - r
        } else {
            r
        };
        self.offset[1] + r
    }
}

/// The lit pixels of a block of [`BLOCK`] grays as bits (bit j: pixel j is at least
/// [`LIT_GRAY`], its high bit set): each word's high bits gathered by one multiplication.
fn lit_bits(block: &[u8]) -> u64 {
    const HIGH: u64 = 0x8080_8080_8080_8080;
    // Byte i's bit 7 lands at bit 56 + i, and no two products meet.
    const GATHER: u64 = 0x0002_0408_1020_4081;
    let mut m = 0;
    for (k, w) in block.chunks_exact(8).enumerate() {
        let high = u64::from_le_bytes(w.try_into().expect("8 bytes")) & HIGH;
        m |= (high.wrapping_mul(GATHER) >> 56) << (8 * k);
    }
    m
}

/// Appends the lit runs (gray ≥ [`LIT_GRAY`]) of `row`, as row `r` with its first pixel
/// at column `base`, to `out`. [`BLOCK`] pixels at a time as bits ([`lit_bits`]): a block
/// of dark pixels outside a run (or of lit ones inside one) costs one test, and in the
/// others each start and end of a run is the next bit where a pixel differs from the one
/// before.
fn row_runs(row: &[u8], r: u32, base: u32, out: &mut Vec<Run>) {
    let mut start: Option<usize> = None;
    let mut push = |s: usize, e: usize| out.push([r, base + s as u32, base + e as u32]);
    let mut toggle = |c: usize, start: &mut Option<usize>| match start.take() {
        None => *start = Some(c),
        Some(s) => push(s, c),
    };
    let blocks = row.chunks_exact(BLOCK);
    let tail = blocks.remainder();
    for (k, block) in blocks.enumerate() {
        let lit = lit_bits(block);
        let inside = start.is_some();
        if (lit == 0 && !inside) || (lit == u64::MAX && inside) {
            continue;
        }
        // Bit j: pixel j differs from pixel j − 1 (the one before the block: `inside`).
        let mut change = lit ^ ((lit << 1) | u64::from(inside));
        while change != 0 {
            toggle(k * BLOCK + change.trailing_zeros() as usize, &mut start);
            change &= change - 1;
        }
    }
    let at = row.len() - tail.len();
    for (j, &v) in tail.iter().enumerate() {
        if (v >= LIT_GRAY) != start.is_some() {
            toggle(at + j, &mut start);
        }
    }
    if let Some(s) = start {
        push(s, row.len());
    }
}

/// The lit runs of the row-major 8-bit image `data`, `width` pixels wide, in its own
/// pixels (row 0 at the top), visiting only `rows` and `cols` (the image dark outside
/// them).
pub fn lit_runs(width: u32, data: &[u8], rows: Range<usize>, cols: Range<usize>) -> Vec<Run> {
    let mut out = Vec::new();
    let w = width as usize;
    if w == 0 || cols.start >= cols.end.min(w) {
        return out;
    }
    let cols = cols.start..cols.end.min(w);
    let rows = data
        .chunks_exact(w)
        .enumerate()
        .take(rows.end)
        .skip(rows.start);
    for (r, row) in rows {
        row_runs(&row[cols.clone()], r as u32, cols.start as u32, &mut out);
    }
    out
}

/// `runs` of a mask moved into the field by `at`: mirrored, then offset; sorted again.
pub fn placed(mut runs: Vec<Run>, at: Placement) -> Vec<Run> {
    let [w, _] = at.size;
    let [ox, _] = at.offset;
    for run in &mut runs {
        let [r, c0, c1] = *run;
        let (c0, c1) = if at.mirror[0] {
            (w - c1, w - c0)
        } else {
            (c0, c1)
        };
        *run = [at.field_row(r), ox + c0, ox + c1];
    }
    if at.mirror[0] || at.mirror[1] {
        runs.sort_unstable();
    }
    runs
}

/// The lit runs of a layer on the field from its masks (row-major 8-bit images, each
/// with its projector's placement): one mask's own lit runs placed, or, for several, each
/// field row's grays added up (saturating) and then thresholded, so a pixel two blended
/// projectors each light by half is lit.
pub fn field_runs(masks: &[(&[u8], Placement)]) -> Vec<Run> {
    match masks {
        [] => Vec::new(),
        [(data, at)] => {
            let [w, h] = at.size.map(|v| v as usize);
            placed(lit_runs(at.size[0], data, 0..h, 0..w), *at)
        }
        _ => composed(masks),
    }
}

/// [`field_runs`] of several masks: row by row over the field rows they cover.
fn composed(masks: &[(&[u8], Placement)]) -> Vec<Run> {
    let cols = |at: &Placement| at.offset[0]..at.offset[0] + at.size[0];
    let rows = |at: &Placement| at.offset[1]..at.offset[1] + at.size[1];
    let x0 = masks.iter().map(|(_, a)| cols(a).start).min().unwrap_or(0);
    let x1 = masks.iter().map(|(_, a)| cols(a).end).max().unwrap_or(0);
    let y0 = masks.iter().map(|(_, a)| rows(a).start).min().unwrap_or(0);
    let y1 = masks.iter().map(|(_, a)| rows(a).end).max().unwrap_or(0);
    let mut line = vec![0u8; (x1 - x0) as usize];
    let mut out = Vec::new();
    for fy in y0..y1 {
        let mut any = false;
        for (data, at) in masks {
            if !rows(at).contains(&fy) {
                continue;
            }
            let [w, h] = at.size.map(|v| v as usize);
            let r = (fy - at.offset[1]) as usize;
            let r = if at.mirror[1] { h - 1 - r } else { r };
            let Some(row) = data.get(r * w..(r + 1) * w) else {
                continue;
            };
            if row.iter().all(|&v| v == 0) {
                continue;
            }
            if !any {
                line.fill(0);
                any = true;
            }
            let dst = &mut line[(at.offset[0] - x0) as usize..][..w];
            if at.mirror[0] {
                for (d, &v) in dst.iter_mut().zip(row.iter().rev()) {
                    *d = d.saturating_add(v);
                }
            } else {
                for (d, &v) in dst.iter_mut().zip(row) {
                    *d = d.saturating_add(v);
                }
            }
        }
        if any {
            row_runs(&line, fy, x0, &mut out);
        }
    }
    out
}

/// The 4-connected components of `runs`: each run's component, numbered from 0 in the
/// order of their first run, and how many (union-find, a component's smallest run its
/// root).
pub fn components(runs: &[Run]) -> (Vec<u32>, usize) {
    fn find(p: &mut [u32], mut x: u32) -> u32 {
        while p[x as usize] != x {
            p[x as usize] = p[p[x as usize] as usize];
            x = p[x as usize];
        }
        x
    }
    let n = runs.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    // The runs of the row above the current run's: `above`, and where the current row
    // starts.
    let (mut above, mut start) = (0..0, 0);
    let mut j = 0;
    for i in 0..n {
        let a = runs[i];
        if i == 0 || runs[i - 1][0] != a[0] {
            above = if i > 0 && runs[i - 1][0] + 1 == a[0] {
                start..i
            } else {
                i..i
            };
            start = i;
            j = above.start;
        }
        while j < above.end && runs[j][2] <= a[1] {
            j += 1;
        }
        let mut t = j;
        while t < above.end && runs[t][1] < a[2] {
            let (x, y) = (find(&mut parent, t as u32), find(&mut parent, i as u32));
            if x != y {
                parent[x.max(y) as usize] = x.min(y);
            }
            t += 1;
        }
    }
    let mut map = vec![u32::MAX; n];
    let mut ids = Vec::with_capacity(n);
    let mut count = 0u32;
    for i in 0..n {
        let root = find(&mut parent, i as u32) as usize;
        if map[root] == u32::MAX {
            map[root] = count;
            count += 1;
        }
        ids.push(map[root]);
    }
    (ids, count as usize)
}

/// Whether each run of `cur` shares a pixel with a run of `below` (same row, overlapping
/// columns), and whether any does not. Both sorted: one merge-walk.
pub fn resting_runs(cur: &[Run], below: &[Run]) -> (Vec<bool>, bool) {
    let mut j = 0;
    let mut all = true;
    let on = cur
        .iter()
        .map(|r| {
            // Skip the runs below that end before this one starts (in this row or earlier).
            while j < below.len()
                && (below[j][0] < r[0] || (below[j][0] == r[0] && below[j][2] <= r[1]))
            {
                j += 1;
            }
            let rests = j < below.len() && below[j][0] == r[0] && below[j][1] < r[2];
            all &= rests;
            rests
        })
        .collect();
    (on, !all)
}

/// A region of a layer's lit pixels that rests on nothing below, in the field's pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// Its lit pixels.
    pub pixels: u64,
    /// Centre of its pixels: column and row (pixel centres at +0.5; row 0 at the top).
    pub col_row: [f64; 2],
    /// The box of its pixels: first column, first row, end column, end row (exclusive).
    pub box_px: [u32; 4],
}

impl Region {
    /// Its centre on the build plane, mm, on a field `field_h_px` rows high of
    /// `pixel_mm` pixels (x from the left edge, y up from the bottom edge).
    pub fn at_mm(&self, field_h_px: u32, pixel_mm: f64) -> [f64; 2] {
        let [c, r] = self.col_row;
        [c * pixel_mm, (field_h_px as f64 - r) * pixel_mm]
    }

    /// Its area, mm².
    pub fn area_mm2(&self, pixel_mm: f64) -> f64 {
        self.pixels as f64 * pixel_mm * pixel_mm
    }
}

/// The 4-connected regions of the lit runs `cur` and which of them rest on the lit runs
/// `below` of the layer below: each run's region (numbered in the order of their first
/// run) and, per region, whether it shares a pixel with `below`. `None` when every run
/// rests on a run below (usually), so that no region rests on nothing.
pub fn resting_regions(cur: &[Run], below: &[Run]) -> Option<(Vec<u32>, Vec<bool>)> {
    let (on, any_free) = resting_runs(cur, below);
    if !any_free {
        return None;
    }
    let (region, n) = components(cur);
    let mut rests = vec![false; n];
    for (&g, &s) in region.iter().zip(&on) {
        rests[g as usize] |= s;
    }
    Some((region, rests))
}

/// Size and centre of the regions of `cur` (each run's region in `region`) that `pick`
/// selects, in region order.
pub fn regions_of(cur: &[Run], region: &[u32], pick: &[bool]) -> Vec<Region> {
    // Per region: pixels, Σ column centres, Σ row centres, box.
    let mut sums = vec![(0u64, 0.0, 0.0, [u32::MAX, u32::MAX, 0, 0]); pick.len()];
    for (&g, r) in region.iter().zip(cur) {
        let len = u64::from(r[2] - r[1]);
        let [row, c0, c1] = r.map(f64::from);
        let t = &mut sums[g as usize];
        let b = &mut t.3;
        *b = [
            b[0].min(r[1]),
            b[1].min(r[0]),
            b[2].max(r[2]),
            b[3].max(r[0] + 1),
        ];
        t.0 += len;
        t.1 += (c0 + c1) / 2.0 * (c1 - c0);
        t.2 += (row + 0.5) * (c1 - c0);
    }
    (0..pick.len())
        .filter(|&g| pick[g])
        .map(|g| {
            let (k, sc, sr, box_px) = sums[g];
            Region {
                pixels: k,
                col_row: [sc / k as f64, sr / k as f64],
                box_px,
            }
        })
        .collect()
}

/// The regions of the lit runs `cur` that share no pixel with the lit runs `below` of
/// the layer below, in the order of their first run. Usually every run rests on a run
/// below and there is none.
pub fn unsupported(cur: &[Run], below: &[Run]) -> Vec<Region> {
    resting_regions(cur, below).map_or(Vec::new(), |(region, rests)| {
        let free: Vec<bool> = rests.iter().map(|r| !r).collect();
        regions_of(cur, &region, &free)
    })
}

/// The regions of every layer that rest on nothing below, with their layer, from each
/// layer's lit runs on the field (`None`: a layer whose masks could not be read; neither
/// it nor the layer above it is judged). Layer 0 rests on the platform.
pub fn unsupported_regions(layers: &[Option<Vec<Run>>]) -> Vec<(usize, Region)> {
    let mut out = Vec::new();
    for (i, pair) in layers.windows(2).enumerate() {
        if let [Some(below), Some(cur)] = pair {
            out.extend(unsupported(cur, below).into_iter().map(|g| (i + 1, g)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{flood_regions as flood, xorshift};

    /// The lit runs of a `w`-wide grid of grays, pixel by pixel.
    fn naive_runs(g: &[u8], w: usize) -> Vec<Run> {
        let mut out = Vec::new();
        for (r, row) in g.chunks(w).enumerate() {
            let mut c = 0;
            while c < w {
                if row[c] >= LIT_GRAY {
                    let s = c;
                    while c < w && row[c] >= LIT_GRAY {
                        c += 1;
                    }
                    out.push([r as u32, s as u32, c as u32]);
                } else {
                    c += 1;
                }
            }
        }
        out
    }

    #[test]
    fn lit_runs_are_those_of_each_pixel() {
        let mut rnd = xorshift(0x7e57_0001);
        for w in [1usize, 7, 8, 9, 16, 31, 63, 64, 65, 100, 130, 200] {
            for _ in 0..40 {
                // Long runs of one gray, so whole words of lit and dark pixels occur.
                let mut g = Vec::with_capacity(w * 5);
                while g.len() < w * 5 {
                    let v = (rnd() * 256.0) as u8;
                    let n = 1 + (rnd() * 20.0) as usize;
                    g.extend(std::iter::repeat_n(v, n));
                }
                g.truncate(w * 5);
                assert_eq!(lit_runs(w as u32, &g, 0..5, 0..w), naive_runs(&g, w), "{w}");
                let rows: Vec<Run> = naive_runs(&g, w)
                    .into_iter()
                    .filter(|r| (1..3).contains(&r[0]))
                    .collect();
                assert_eq!(lit_runs(w as u32, &g, 1..3, 0..w), rows);
            }
        }
    }

    #[test]
    fn regions_match_a_pixel_flood_fill() {
        let mut rnd = xorshift(0x2e61_0115);
        let (w, h) = (23usize, 17usize);
        let mut total = 0;
        for case in 0..300 {
            let (pc, pb) = (0.3 + 0.4 * rnd(), 0.1 + 0.6 * rnd());
            let gray = |p: f64, rnd: &mut dyn FnMut() -> f64| -> Vec<u8> {
                (0..w * h)
                    .map(|_| {
                        if rnd() < p {
                            128 + (rnd() * 127.0) as u8
                        } else {
                            (rnd() * 127.0) as u8
                        }
                    })
                    .collect()
            };
            let (cur, below) = (gray(pc, &mut rnd), gray(pb, &mut rnd));
            let lit = |g: &[u8]| g.iter().map(|&v| v >= LIT_GRAY).collect::<Vec<_>>();
            let mut want = flood(&lit(&cur), &lit(&below), w, h);
            let rc = lit_runs(w as u32, &cur, 0..h, 0..w);
            let rb = lit_runs(w as u32, &below, 0..h, 0..w);
            let mut got: Vec<(u64, f64, f64)> = unsupported(&rc, &rb)
                .iter()
                .map(|g| {
                    let k = g.pixels as f64;
                    (g.pixels, g.col_row[0] * k, g.col_row[1] * k)
                })
                .collect();
            let key =
                |t: &(u64, f64, f64)| (t.0, (t.1 * 2.0).round() as i64, (t.2 * 2.0).round() as i64);
            want.sort_by_key(key);
            got.sort_by_key(key);
            assert_eq!(
                got.iter().map(key).collect::<Vec<_>>(),
                want.iter().map(key).collect::<Vec<_>>(),
                "case {case}"
            );
            total += want.len();
        }
        assert!(total > 300, "{total}");
    }

    #[test]
    fn layers_over_layers_and_the_platform() {
        // Layer 0: a 4-pixel run (on the platform). Layer 1: a run on it and one beside
        // it. Layer 2 unreadable: neither it nor layer 3 is judged.
        let layers = vec![
            Some(vec![[0, 0, 4]]),
            Some(vec![[0, 2, 5], [2, 10, 13], [3, 10, 13]]),
            None,
            Some(vec![[9, 9, 10]]),
            Some(vec![[9, 0, 1]]),
        ];
        let found = unsupported_regions(&layers);
        assert_eq!(
            found,
            vec![
                (
                    1,
                    Region {
                        pixels: 6,
                        col_row: [11.5, 3.0],
                        box_px: [10, 2, 13, 4],
                    }
                ),
                (
                    4,
                    Region {
                        pixels: 1,
                        col_row: [0.5, 9.5],
                        box_px: [0, 9, 1, 10],
                    }
                )
            ]
        );
        // On a 10-row field of 0.5 mm pixels: x 5.75, y (10 − 3) × 0.5 mm, 1.5 mm².
        assert_eq!(found[0].1.at_mm(10, 0.5), [5.75, 3.5]);
        assert_eq!(found[0].1.area_mm2(0.5), 1.5);
    }

    #[test]
    fn masks_are_placed_and_blended_projectors_added_up() {
        // A 6×4 mask lighting columns 1..3 of row 0 and column 5 of row 3.
        let mut m = vec![0u8; 24];
        m[1] = 200;
        m[2] = 255;
        m[3 * 6 + 5] = 130;
        let at = |offset, mirror| Placement {
            size: [6, 4],
            offset,
            mirror,
        };
        assert_eq!(
            field_runs(&[(&m, at([10, 20], [false, false]))]),
            vec![[20, 11, 13], [23, 15, 16]]
        );
        // Mirrored in x and y: columns 1..3 → 3..5, column 5 → 0; row 0 → 3, row 3 → 0.
        assert_eq!(
            field_runs(&[(&m, at([10, 20], [true, true]))]),
            vec![[20, 10, 11], [23, 13, 15]]
        );
        // Two projectors overlapping by 2 columns, each lighting the overlap by 100: lit
        // only together.
        let (mut a, mut b) = (vec![0u8; 24], vec![0u8; 24]);
        a[6 + 3] = 255;
        a[6 + 4] = 100;
        a[6 + 5] = 100;
        b[6] = 100;
        b[6 + 1] = 100;
        b[6 + 2] = 255;
        let two = [
            (&a[..], at([0, 0], [false, false])),
            (&b[..], at([4, 0], [false, false])),
        ];
        assert_eq!(field_runs(&two), vec![[1, 3, 7]]);
        assert_eq!(field_runs(&two[..1]), vec![[1, 3, 4]]);
        assert_eq!(field_runs(&[]), Vec::<Run>::new());
    }
}
