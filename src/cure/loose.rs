//! Pieces of a corrected layer that would cure loose. The correction moves edges in by
//! the cure's growth and leaves partial grays that only the blur joins, so where a
//! section runs out in a sliver (the thin rim of a surface that faces down, a corner
//! beside a support's head) its lit pixels may break up: a lone pixel of the sliver cures
//! on its own while the grays between it and the rest of the layer do not, and that speck
//! cures in the vat, apart from the part. [`loose_pieces`] finds such pieces, judged as
//! `run` judges a corrected job's regions (docs/EXECUTOR.md, "Printability"), against
//! the layer below as it was drawn ([`Drawn`]):
//!
//! * the candidates are the 4-connected pieces of lit pixels (gray ≥ [`LIT_GRAY`]) of
//!   the corrected coverage no larger than a support head's contact, none of whose pixels
//!   is lit in the layer below (larger pieces are the islands analysis' and the
//!   supports', but for the bridges below);
//! * a candidate rests when what cures of it (the light, coverage / 255, blurred by the
//!   PSF, at least the layer's threshold), grown through what cures of its layer, meets
//!   what cures of the layer below, a larger piece or a candidate that rests;
//! * one that cures and rests on nothing is loose when the section's exact coverage joins
//!   it, through lit pixels, to a pixel lit in the layer below within its window: the
//!   correction split it off a region that rests. A piece that is an island of the
//!   section itself is left as it is (the islands analysis reports it, the supports hold
//!   it).
//!
//! The job draws loose pieces dark: a speck that would cure loose is left out of the part.
//! A larger piece none of whose pixels lies on a pixel fully lit in the layer below (which
//! the grays show lit whatever the compensation: `run` reads the grays) is joined back
//! when the exact coverage joins it, through lit pixels within its window, to such a
//! pixel (the correction cut the neck that held it): a shortest such path is drawn at
//! full light, a bridge.

use crate::bundle::regions::{components, lit_runs, Run, LIT_GRAY};
use crate::cure::Psf;
use crate::raster::{Mask, PixelBox};

/// A layer's corrected coverage over its lit box, as its masks show it before the light
/// compensation, and the light at which it cures: the layer below's, for the next
/// layer's judgment.
pub struct Drawn {
    lit: PixelBox,
    /// The field's width, pixels.
    width: usize,
    /// The lit box's rows.
    data: Vec<u8>,
    t: f32,
}

impl Drawn {
    /// The corrected coverage `m` (dark outside `lit`), curing at `t`.
    pub fn of(m: &Mask, lit: PixelBox, t: f32) -> Drawn {
        let w = m.width as usize;
        let mut data = Vec::with_capacity(lit.rows().len() * lit.cols().len());
        for r in lit.rows() {
            data.extend_from_slice(&m.data[r * w..][lit.cols()]);
        }
        Drawn {
            lit,
            width: w,
            data,
            t,
        }
    }

    /// The same box of `m`, drawn again after it (curing at the same threshold).
    pub fn redrawn(self, m: &Mask) -> Drawn {
        Drawn::of(m, self.lit, self.t)
    }

    /// The coverage at mask index `k`.
    fn at(&self, k: usize) -> u8 {
        let (r, c) = (k / self.width, k % self.width);
        let b = &self.lit;
        if b.rows().contains(&r) && b.cols().contains(&c) {
            self.data[(r - b.r0) * b.cols().len() + c - b.c0]
        } else {
            0
        }
    }
}

/// A window's pixel outside the pieces judged ([`labels`]).
pub const OUT: u8 = 0;
/// A pixel of the piece judged.
pub const OWN: u8 = 1;
/// A pixel of a piece that rests.
pub const RESTING: u8 = 2;

/// What [`loose_pieces`] finds in a corrected layer, as mask indices.
#[derive(Debug, Default, PartialEq)]
pub struct Loose {
    /// The lit pixels of the loose pieces: to draw dark.
    pub dark: Vec<usize>,
    /// The bridges that join the larger pieces the correction split off back to what rests:
    /// to draw at full light.
    pub bridges: Vec<usize>,
}

/// The loose pieces of the corrected coverage `m` (lit box `lit`; see the module docs) and
/// the bridges of its larger split-off pieces. `psf`, `t`: the blur and the relative light
/// at which the layer's resin cures (the model's edge threshold over the layer's dose
/// against the normal layer's); `max_px`: the largest candidate, pixels; `bridge`: whether
/// to bridge the larger pieces (not where the Z correction holds layers back: their dark
/// pixels are meant); `exact`: the layer's coverage before the correction, drawn when a
/// piece needs it.
pub fn loose_pieces(
    m: &Mask,
    lit: PixelBox,
    (psf, t): (&Psf, f32),
    (max_px, bridge): (usize, bool),
    below: Option<&Drawn>,
    exact: &mut dyn FnMut() -> Mask,
) -> Loose {
    let mut out = Loose::default();
    // A block's first layer: the layer below is another worker's.
    let Some(under) = below else {
        return out;
    };
    let w = m.width as usize;
    let runs = lit_runs(m.width, &m.data, lit.rows(), lit.cols());
    let (ids, n) = components(&runs);
    let mut size = vec![0usize; n];
    for (r, &g) in runs.iter().zip(&ids) {
        size[g as usize] += (r[2] - r[1]) as usize;
    }
    // Per piece, whether one of its pixels lies on a pixel lit below, and on one fully lit
    // (which the grays show lit whatever the compensation).
    let (mut on_lit, mut on_full) = (vec![false; n], vec![false; n]);
    for (r, &g) in runs.iter().zip(&ids) {
        let row = r[0] as usize * w;
        let g = g as usize;
        for c in r[1]..r[2] {
            if on_full[g] {
                break;
            }
            let v = under.at(row + c as usize);
            on_lit[g] |= v >= LIT_GRAY;
            on_full[g] = v == u8::MAX;
        }
    }
    if on_full.iter().all(|&f| f) {
        return out;
    }
    // Resting: the pieces on a lit pixel; to the candidates, the larger pieces as well.
    let mut rests: Vec<bool> = (0..n).map(|g| on_lit[g] || size[g] > max_px).collect();
    let pixels = |g: u32| {
        runs.iter()
            .zip(&ids)
            .filter(move |(_, &k)| k == g)
            .flat_map(move |(r, _)| (r[1]..r[2]).map(move |c| r[0] as usize * w + c as usize))
    };
    let mut exact_m: Option<Mask> = None;
    let judge = Judge {
        m,
        under,
        psf,
        t,
        runs: &runs,
        ids: &ids,
    };
    let window = |g: usize| Window::of((&runs, &ids), g as u32, psf, [w, m.height as usize]);
    for g in 0..n {
        if rests[g] {
            continue;
        }
        let win = window(g);
        match judge.cured(g as u32, &win, &rests) {
            Cured::Rests => rests[g] = true,
            Cured::Nothing => {}
            Cured::Free => {
                let e = exact_m.get_or_insert_with(&mut *exact);
                if judge.joining_path(g as u32, &win, e, LIT_GRAY).is_some() {
                    out.dark.extend(pixels(g as u32));
                }
            }
        }
    }
    // The larger pieces on no pixel fully lit below, bridged to one.
    for g in (0..n).filter(|&g| bridge && size[g] > max_px && !on_full[g]) {
        let e = exact_m.get_or_insert_with(&mut *exact);
        out.bridges.extend(
            judge
                .joining_path(g as u32, &window(g), e, u8::MAX)
                .unwrap_or_default(),
        );
    }
    out
}

/// What cures of a candidate piece (here and in `run`'s judgment of a corrected job's
/// regions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cured {
    /// Meets the layer below or a resting piece of its layer.
    Rests,
    /// Rests on nothing within its window.
    Free,
    /// None of its pixels cures.
    Nothing,
}

/// The window `rows` × `cols` (row-major) of a layer's pieces: [`OWN`] where piece `g`
/// lies, [`RESTING`] where a piece `rests` says rests, else [`OUT`]. `runs`: the layer's
/// lit runs, `ids`: each one's piece.
pub fn labels(
    (runs, ids): (&[Run], &[u32]),
    g: u32,
    rests: &[bool],
    rows: &std::ops::Range<usize>,
    cols: &std::ops::Range<usize>,
) -> Vec<u8> {
    let ww = cols.len();
    let mut label = vec![OUT; ww * rows.len()];
    for (run, &k) in runs.iter().zip(ids) {
        let r = run[0] as usize;
        if !rows.contains(&r) || !(k == g || rests[k as usize]) {
            continue;
        }
        let a = (run[1] as usize).max(cols.start);
        let b = (run[2] as usize).min(cols.end);
        let v = if k == g { OWN } else { RESTING };
        for c in a..b {
            label[(r - rows.start) * ww + c - cols.start] = v;
        }
    }
    label
}

/// What cures of the piece labelled [`OWN`] in `label` (a window `ww` wide, from
/// [`labels`]): grown from its pixels that cure (`cures`) through the pixels of its layer
/// that cure, whether it meets one where the layer below cures (`below`) or a resting
/// piece.
pub fn judged(label: &[u8], cures: &[bool], below: &[bool], ww: usize) -> Cured {
    let seeds: Vec<usize> = (0..label.len())
        .filter(|&k| label[k] == OWN && cures[k])
        .collect();
    if seeds.is_empty() {
        return Cured::Nothing;
    }
    match shortest_path(ww, &seeds, cures, |k| below[k] || label[k] == RESTING) {
        Some(_) => Cured::Rests,
        None => Cured::Free,
    }
}

/// A candidate's window: its box and twice the PSF's reach around it, rows × columns.
pub struct Window {
    /// Rows.
    pub rows: std::ops::Range<usize>,
    /// Columns.
    pub cols: std::ops::Range<usize>,
}

impl Window {
    /// The window of piece `g` of a layer's lit runs (`runs`, each one's piece `ids`) on a
    /// field `[width, height]` pixels, blurred by `psf`.
    pub fn of((runs, ids): (&[Run], &[u32]), g: u32, psf: &Psf, [w, h]: [usize; 2]) -> Window {
        let (mut r0, mut c0, mut r1, mut c1) = (usize::MAX, usize::MAX, 0, 0);
        for (run, _) in runs.iter().zip(ids).filter(|(_, &k)| k == g) {
            let [r, a, b] = run.map(|v| v as usize);
            (r0, r1, c0, c1) = (r0.min(r), r1.max(r + 1), c0.min(a), c1.max(b));
        }
        let margin = 2 * psf.reach_whole_px() + 2;
        Window {
            rows: r0.saturating_sub(margin)..(r1 + margin).min(h),
            cols: c0.saturating_sub(margin)..(c1 + margin).min(w),
        }
    }

    /// The window's pixels as mask indices, row-major.
    fn indices(&self, w: usize) -> impl Iterator<Item = usize> + '_ {
        self.rows
            .clone()
            .flat_map(move |r| self.cols.clone().map(move |c| r * w + c))
    }
}

/// One layer's candidates and what they are judged by.
struct Judge<'a> {
    m: &'a Mask,
    under: &'a Drawn,
    psf: &'a Psf,
    t: f32,
    runs: &'a [Run],
    ids: &'a [u32],
}

impl Judge<'_> {
    /// What cures of candidate `g` within `win` (module docs); `rests`: each piece's.
    fn cured(&self, g: u32, win: &Window, rests: &[bool]) -> Cured {
        let w = self.m.width as usize;
        let label = labels((self.runs, self.ids), g, rests, &win.rows, &win.cols);
        let h = self.m.height as usize;
        // Off the field: 0.
        let at = |r: Option<usize>, c: Option<usize>| match r.zip(c) {
            Some((r, c)) if r < h && c < w => Some(r * w + c),
            _ => None,
        };
        let (rows, cols) = (&win.rows, &win.cols);
        let light = |r, c| at(r, c).map_or(0.0, |k| self.m.data[k] as f32 / 255.0);
        let cures = self.psf.cures_in(rows.clone(), cols.clone(), self.t, light);
        let light = |r, c| at(r, c).map_or(0.0, |k| self.under.at(k) as f32 / 255.0);
        let below = self
            .psf
            .cures_in(rows.clone(), cols.clone(), self.under.t, light);
        judged(&label, &cures, &below, cols.len())
    }

    /// The shortest path (mask indices) by which the exact coverage `exact` joins piece
    /// `g`, through its 4-connected lit pixels within `win`, to a pixel of the layer below
    /// of coverage `full` or more: the path's pixels that are not the piece's (none when a
    /// pixel of the piece is one), or `None` when it does not join them.
    fn joining_path(&self, g: u32, win: &Window, exact: &Mask, full: u8) -> Option<Vec<usize>> {
        let w = self.m.width as usize;
        let ww = win.cols.len();
        let at = |k: usize| (k / w - win.rows.start) * ww + (k % w - win.cols.start);
        let lit: Vec<bool> = win.indices(w).map(|k| exact.data[k] >= LIT_GRAY).collect();
        let own: Vec<usize> = self
            .runs
            .iter()
            .zip(self.ids)
            .filter(|(_, &k)| k == g)
            .flat_map(|(r, _)| (r[1]..r[2]).map(move |c| r[0] as usize * w + c as usize))
            .map(at)
            .filter(|&k| lit[k])
            .collect();
        let goal = |k: usize| {
            let (r, c) = (k / ww + win.rows.start, k % ww + win.cols.start);
            self.under.at(r * w + c) >= full
        };
        let path = shortest_path(ww, &own, &lit, goal)?;
        let mut mine = vec![false; lit.len()];
        own.iter().for_each(|&k| mine[k] = true);
        Some(
            path.into_iter()
                .filter(|&k| !mine[k])
                .map(|k| (k / ww + win.rows.start) * w + k % ww + win.cols.start)
                .collect(),
        )
    }
}

/// The shortest path from `seeds` through the 4-connected pixels of `through` (a window
/// `ww` wide) to a pixel where `goal` holds, seed first (breadth first: the first seed and
/// neighbour in order among equals); `None` when there is none.
fn shortest_path(
    ww: usize,
    seeds: &[usize],
    through: &[bool],
    goal: impl Fn(usize) -> bool,
) -> Option<Vec<usize>> {
    // Each reached pixel's predecessor (a seed its own); `UNSEEN` before it is reached.
    const UNSEEN: usize = usize::MAX;
    let mut from = vec![UNSEEN; through.len()];
    let mut queue = std::collections::VecDeque::new();
    for &k in seeds {
        if from[k] == UNSEEN {
            from[k] = k;
            queue.push_back(k);
        }
    }
    while let Some(k) = queue.pop_front() {
        if goal(k) {
            let mut path = vec![k];
            while from[path[path.len() - 1]] != path[path.len() - 1] {
                path.push(from[path[path.len() - 1]]);
            }
            path.reverse();
            return Some(path);
        }
        let (x, y, wh) = (k % ww, k / ww, through.len() / ww);
        let next = [
            (x > 0).then(|| k - 1),
            (x + 1 < ww).then(|| k + 1),
            (y > 0).then(|| k - ww),
            (y + 1 < wh).then(|| k + ww),
        ];
        for n in next.into_iter().flatten() {
            if through[n] && from[n] == UNSEEN {
                from[n] = k;
                queue.push_back(n);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 60;

    fn block(m: &mut Mask, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>, g: u8) {
        for r in rows {
            for c in cols.clone() {
                m.data[r * W as usize + c] = g;
            }
        }
    }

    /// A block lit on the layer below and in this layer, corrected; `extra` adds this
    /// layer's other pixels, `exact` its coverage before the correction. The loose pixels.
    fn judge(
        extra: &[(usize, usize, u8)],
        exact: &[(usize, usize, u8)],
        below: bool,
    ) -> Vec<(usize, usize)> {
        found(extra, exact, below, true).0
    }

    /// [`judge`]'s loose pixels and bridges (`bridge`: whether to draw them).
    #[allow(clippy::type_complexity)]
    fn found(
        extra: &[(usize, usize, u8)],
        exact: &[(usize, usize, u8)],
        below: bool,
        bridge: bool,
    ) -> (Vec<(usize, usize)>, Vec<(usize, usize)>) {
        let mut m = Mask::zeros(W, W);
        block(&mut m, 10..30, 10..30, 255);
        let mut e = m.clone();
        for &(r, c, g) in extra {
            m.data[r * W as usize + c] = g;
        }
        for &(r, c, g) in exact {
            e.data[r * W as usize + c] = g;
        }
        let lit = PixelBox {
            r0: 0,
            r1: W as usize,
            c0: 0,
            c1: W as usize,
        };
        let mut under = Mask::zeros(W, W);
        block(&mut under, 10..30, 10..30, 255);
        let under = below.then(|| Drawn::of(&under, lit, 0.3));
        let psf = Psf { sigma_px: 0.5 };
        let mut exact = || e.clone();
        let found = loose_pieces(
            &m,
            lit,
            (&psf, 0.3),
            (31, bridge),
            under.as_ref(),
            &mut exact,
        );
        let rc = |px: Vec<usize>| {
            px.iter()
                .map(|&k| (k / W as usize, k % W as usize))
                .collect()
        };
        (rc(found.dark), rc(found.bridges))
    }

    /// A sliver from the block's corner to (33, 35) in the exact coverage.
    fn sliver() -> Vec<(usize, usize, u8)> {
        (30..34)
            .flat_map(|r| (29..36).map(move |c| (r, c, 200)))
            .collect()
    }

    #[test]
    fn a_lone_curing_pixel_split_off_a_resting_region_is_loose() {
        // Corrected, the sliver keeps one lit pixel, dark ones between it and the block.
        let found = judge(&[(32, 35, 200)], &sliver(), true);
        assert_eq!(found, [(32, 35)]);
        // On the platform, nothing is loose.
        assert!(judge(&[(32, 35, 200)], &sliver(), false).is_empty());
    }

    #[test]
    fn an_island_of_the_section_and_a_pixel_that_cures_with_the_block_are_kept() {
        // The exact coverage has the pixel alone: an island, the supports' to hold.
        assert!(judge(&[(32, 35, 200)], &[(32, 35, 200)], true).is_empty());
        // Diagonal to the block's corner, grays between it and the block that cure with
        // them: it rests through its layer.
        let joined = [(30, 30, 200), (30, 29, 120), (29, 30, 120)];
        assert!(judge(&joined, &sliver(), true).is_empty());
        // The same pixel without the grays cures alone.
        assert_eq!(judge(&[(30, 30, 200)], &sliver(), true), [(30, 30)]);
        // Too dim to cure at all: nothing to leave out.
        assert!(judge(&[(32, 35, 130)], &sliver(), true).is_empty());
    }

    #[test]
    fn a_piece_larger_than_a_heads_contact_split_off_is_bridged_back() {
        // 7 × 5 pixels past three dark rows, joined to the block by the sliver: not drawn
        // dark, but joined back by a shortest path through the sliver to the block's
        // corner (29, 29), 6 pixels from the piece's corner (33, 31).
        let piece: Vec<_> = (33..40)
            .flat_map(|r| (31..36).map(move |c| (r, c, 255)))
            .collect();
        let mut exact = sliver();
        exact.extend(piece.iter().copied());
        assert_eq!(
            found(&piece, &exact, true, true),
            (
                vec![],
                vec![(33, 30), (33, 29), (32, 29), (31, 29), (30, 29), (29, 29)]
            )
        );
        // An island of the section (nothing joins it) is left to the supports; on the
        // platform nothing is judged; without bridges (xyz) it stays as it is.
        assert_eq!(found(&piece, &piece, true, true), (vec![], vec![]));
        assert_eq!(found(&piece, &exact, false, true), (vec![], vec![]));
        assert_eq!(found(&piece, &exact, true, false), (vec![], vec![]));
        // Smaller than the contact, it is drawn dark.
        assert_eq!(found(&piece[..30], &exact, true, true).0.len(), 30);
    }
}
