//! Where support points go: under every island (a region of a layer that rests on nothing
//! below) and under surfaces that face down at less than the critical angle, spread so
//! that every such pixel lies within `spacing / √2` of a point.
//!
//! Each layer's needs are found on its own (in parallel): its islands, and its
//! down-facing pixels, those new in the layer (not lit in the layer below) and farther
//! than `j` self-supporting distances plus one pixel from the layer `j` = 4 below (over
//! several layers the pixel grid's steps average out, so a steep wall is not taken for an
//! overhang). Then the points are placed layer by layer from the bottom, since a point
//! covers pixels of the layers above it too: a down-facing pixel is covered by a point
//! within `spacing / √2` of it placed at most as many layers lower as a surface at the
//! critical angle climbs over that distance. Every island gets a point at its most
//! interior pixel (or, crowded by a point below, its deepest pixel clear of it when that
//! lies a head's contact inside), unless a head of the same layer nearer than a pillar's
//! diameter touches it already; the other points go to the first uncovered pixel in scan order,
//! moved inward when the pixel there is down-facing too, and never closer than a pillar's
//! diameter to a point of the same reach.

use super::runs::{self, Run};
use crate::cure::islands::components;
use rayon::prelude::*;
use std::collections::HashMap;

/// Pixels an island must share with the layer below to count as resting on it: a region
/// that touches the layer below in fewer pixels gets a point (its hold would not survive
/// an edge moved by the cure correction).
pub const MIN_SHARED_PX: u32 = 3;
/// Layers below a layer its down-facing pixels are measured from.
const LOOK_BACK: usize = 4;

/// A support point: where a head touches the part from below.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Column and row of its pixel in the field.
    pub col_row: [u32; 2],
    /// The layer it supports (its head touches the bottom of this layer).
    pub layer: usize,
    /// Whether it holds an island (else a surface facing down).
    pub island: bool,
}

/// How points are spread, in pixels and layers.
#[derive(Debug, Clone, Copy)]
pub struct Spread {
    /// Field width, pixels.
    pub width: u32,
    /// A point covers pixels this close, pixels.
    pub cover_px: f64,
    /// Points of the same reach are never closer, pixels.
    pub min_apart_px: f64,
    /// A point covers pixels of layers up to this many above its own.
    pub reach_layers: usize,
    /// Self-supporting distance per layer, pixels.
    pub self_px: f64,
    /// A head's contact reaches this far, pixels.
    pub contact_px: f64,
    /// The part's first layer rests on the pad (elevation 0): it needs no points.
    pub first_on_pad: bool,
    /// The job's cure correction moves edges in: a region rests on the layer below only
    /// where the pixels they share keep one whose four neighbours they share too.
    pub firm_hold: bool,
}

/// What a layer needs: its islands (each as runs) and its pixels that face down (the
/// islands' included).
#[derive(Debug, Default)]
struct Needs {
    islands: Vec<Vec<Run>>,
    down: Vec<Run>,
}

/// The support points of the part whose lit pixels per layer are `masks` (layers below
/// `first` are empty).
pub fn place(masks: &[Vec<Run>], first: usize, s: &Spread) -> Vec<Point> {
    // Each layer's erosion (for the necks), once: it is its own and the next one's below.
    let cores: Vec<Vec<Run>> = match s.firm_hold {
        true => masks.par_iter().map(|m| runs::eroded(m)).collect(),
        false => Vec::new(),
    };
    let needs: Vec<Needs> = (0..masks.len())
        .into_par_iter()
        .map(|l| {
            if l < first {
                Needs::default()
            } else {
                needs((masks, &cores), first, l, s)
            }
        })
        .collect();
    let mut placed = Placed::new(s);
    for (l, need) in needs.iter().enumerate() {
        for island in &need.islands {
            let [c, r] = interior(island);
            // A head of this layer that touches the island already holds it (islands a
            // pixel or two apart would otherwise get pillars that overlap all the way down).
            let held = placed
                .near(c as f64, r as f64, l, s.min_apart_px)
                .filter(|q| q.layer == l)
                .any(|q| {
                    let [qc, qr] = q.col_row.map(|v| v as f64 + 0.5);
                    runs::any_within(island, qc, qr, s.contact_px)
                });
            if !held {
                placed.push(Point {
                    col_row: placed.apart_within(island, [c, r], l),
                    layer: l,
                    island: true,
                });
            }
        }
        for &run in &need.down {
            placed.cover_run(run, l, &need.down);
        }
    }
    placed.points
}

/// What layer `l` needs (`cores`: each layer's erosion, with the firm hold).
fn needs((masks, cores): (&[Vec<Run>], &[Vec<Run>]), first: usize, l: usize, s: &Spread) -> Needs {
    let cur = &masks[l];
    if cur.is_empty() || (l == first && s.first_on_pad) {
        return Needs::default();
    }
    let (region, n) = components(cur);
    let prev: &[Run] = if l == first { &[] } else { &masks[l - 1] };
    let mut shared = vec![0u32; n];
    for (g, k) in region.iter().zip(runs::shared_pixels(cur, prev)) {
        shared[*g as usize] += k;
    }
    let mut regions: Vec<Vec<Run>> = vec![Vec::new(); n];
    for (g, r) in region.iter().zip(cur) {
        regions[*g as usize].push(*r);
    }
    let mut islands: Vec<Vec<Run>> = regions
        .into_iter()
        .zip(shared)
        .filter(|(r, k)| *k < MIN_SHARED_PX || (s.firm_hold && !firm(r, prev)))
        .map(|(r, _)| r)
        .collect();
    if s.firm_hold {
        let below: &[Run] = if l == first { &[] } else { &cores[l - 1] };
        islands.extend(cut_off(&cores[l], below));
    }
    let mut down = if l == first {
        Vec::new()
    } else {
        let fresh = runs::minus(cur, prev);
        let j = LOOK_BACK.min(l - first);
        let reach = j as f64 * s.self_px + 1.0;
        runs::beyond(&fresh, &masks[l - j], reach, s.width)
    };
    for i in &islands {
        down = runs::union(&down, i);
    }
    Needs { islands, down }
}

/// Whether `region` holds on `below` where edges move in by up to a pixel: some pixel
/// they share has its four neighbours shared too (a hold a pixel or two wide does not
/// survive the cure correction's moves of both layers' edges). A region that is itself a
/// pixel or two wide everywhere (a thin wall or pin, which the correction draws wider so
/// that it cures) holds as it is drawn.
fn firm(region: &[Run], below: &[Run]) -> bool {
    !runs::has_interior(region)
        || runs::has_interior(&runs::minus(region, &runs::minus(region, below)))
}

/// The parts of a layer that hang from the rest of their region by a neck a pixel or two
/// wide and rest on nothing firm below: the components of its pixels whose four
/// neighbours are lit (its erosion by a pixel, `core`) that share no such pixel with the
/// layer below (its erosion `below`). The cure correction, moving edges in, cuts such a
/// neck, and the part it held would cure loose.
fn cut_off(core: &[Run], below: &[Run]) -> Vec<Vec<Run>> {
    if core.is_empty() {
        return Vec::new();
    }
    let (part, n) = components(core);
    let mut rests = vec![false; n];
    for (g, k) in part.iter().zip(runs::shared_pixels(core, below)) {
        rests[*g as usize] |= k > 0;
    }
    let mut out: Vec<Vec<Run>> = vec![Vec::new(); n];
    for (g, r) in part.iter().zip(core) {
        if !rests[*g as usize] {
            out[*g as usize].push(*r);
        }
    }
    out.retain(|p| !p.is_empty());
    out
}

/// The pixel of a region farthest from its outside (chamfer distance, 3-4 weights; the
/// first in scan order among equals).
fn interior(region: &[Run]) -> [u32; 2] {
    deepest(region, |_, _| true).map_or([region[0][1], region[0][0]], |(_, p)| p)
}

/// The pixel of a region farthest from its outside among those `keep` accepts, with its
/// chamfer distance (3 per pixel straight, 4 diagonal; the first in scan order among
/// equals).
fn deepest(region: &[Run], keep: impl Fn(u32, u32) -> bool) -> Option<(u32, [u32; 2])> {
    let r0 = region[0][0];
    let r1 = region.iter().map(|r| r[0]).max().unwrap_or(r0) + 1;
    let c0 = region.iter().map(|r| r[1]).min().unwrap_or(0);
    let c1 = region.iter().map(|r| r[2]).max().unwrap_or(c0 + 1);
    let (w, h) = ((c1 - c0) as usize + 2, (r1 - r0) as usize + 2);
    // One cell of border around the box, outside the region.
    let mut d = vec![0u32; w * h];
    for &[row, a, b] in region {
        let y = (row - r0) as usize + 1;
        for x in (a - c0) as usize + 1..(b - c0) as usize + 1 {
            d[y * w + x] = u32::MAX / 2;
        }
    }
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            if d[i] > 0 {
                d[i] = d[i]
                    .min(d[i - 1] + 3)
                    .min(d[i - w] + 3)
                    .min(d[i - w - 1] + 4)
                    .min(d[i - w + 1] + 4);
            }
        }
    }
    for y in (1..h - 1).rev() {
        for x in (1..w - 1).rev() {
            let i = y * w + x;
            if d[i] > 0 {
                d[i] = d[i]
                    .min(d[i + 1] + 3)
                    .min(d[i + w] + 3)
                    .min(d[i + w + 1] + 4)
                    .min(d[i + w - 1] + 4);
            }
        }
    }
    let mut best: Option<(u32, [u32; 2])> = None;
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let (depth, at) = (d[y * w + x], [c0 + x as u32 - 1, r0 + y as u32 - 1]);
            if depth > best.map_or(0, |b| b.0) && keep(at[0], at[1]) {
                best = Some((depth, at));
            }
        }
    }
    best
}

/// The points placed so far, in cells of `cover_px` for the nearness queries.
struct Placed<'s> {
    s: &'s Spread,
    points: Vec<Point>,
    cells: HashMap<(i64, i64), Vec<u32>>,
}

impl<'s> Placed<'s> {
    fn new(s: &'s Spread) -> Self {
        Placed {
            s,
            points: Vec::new(),
            cells: HashMap::new(),
        }
    }

    fn cell(&self, c: f64, r: f64) -> (i64, i64) {
        let k = self.s.cover_px.max(1.0);
        ((c / k).floor() as i64, (r / k).floor() as i64)
    }

    fn push(&mut self, p: Point) {
        let key = self.cell(p.col_row[0] as f64, p.col_row[1] as f64);
        self.cells
            .entry(key)
            .or_default()
            .push(self.points.len() as u32);
        self.points.push(p);
    }

    /// The points that reach layer `l` within `radius` pixels of (`c`, `r`).
    fn near(&self, c: f64, r: f64, l: usize, radius: f64) -> impl Iterator<Item = &Point> + '_ {
        let (lo, hi) = (
            self.cell(c - radius, r - radius),
            self.cell(c + radius, r + radius),
        );
        let reach = self.s.reach_layers;
        (lo.1..=hi.1)
            .flat_map(move |y| (lo.0..=hi.0).map(move |x| (x, y)))
            .filter_map(|k| self.cells.get(&k))
            .flatten()
            .map(|&i| &self.points[i as usize])
            .filter(move |p| {
                let (dc, dr) = (p.col_row[0] as f64 - c, p.col_row[1] as f64 - r);
                p.layer <= l && l - p.layer <= reach && dc * dc + dr * dr <= radius * radius
            })
    }

    /// `at`, or when it lies within a pillar's diameter of a point reaching layer `l`, the
    /// deepest pixel of `region` that lies that far from every such point, if it lies deep
    /// enough: so that the pillars do not overlap.
    fn apart_within(&self, region: &[Run], at: [u32; 2], l: usize) -> [u32; 2] {
        let d = self.s.min_apart_px;
        let clear = |c: u32, r: u32| self.near(c as f64, r as f64, l, d).next().is_none();
        if clear(at[0], at[1]) {
            return at;
        }
        // The deepest clear pixel, if it lies as deep as a head's contact reaches (or as
        // the region's most interior pixel): a point at the region's edge would hold it
        // by a sliver that the cure correction's moves take away. Else the most interior
        // pixel, its pillar near another's.
        let depth = |p: Option<(u32, [u32; 2])>| p.map_or(0, |p| p.0);
        let want = depth(deepest(region, |c, r| [c, r] == at))
            .min(3 * self.s.contact_px.round().max(2.0) as u32);
        match deepest(region, clear) {
            Some((k, p)) if k >= want => p,
            _ => at,
        }
    }

    /// Places points on layer `l` until every pixel of `run` is covered; `down` is the
    /// layer's down-facing set (where a point may move inward to).
    fn cover_run(&mut self, [row, a, b]: Run, l: usize, down: &[Run]) {
        let cover = self.s.cover_px;
        let mut x = a;
        while x < b {
            // Covered: on past the last pixel the covering point reaches in this row.
            if let Some(q) = self.near(x as f64, row as f64, l, cover).next() {
                let dr = q.col_row[1] as f64 - row as f64;
                let reach = q.col_row[0] as f64 + (cover * cover - dr * dr).sqrt();
                x = (reach.floor() as u32 + 1).max(x + 1);
                continue;
            }
            let step = 0.7 * cover / std::f64::consts::SQRT_2;
            let at = [step, step / 2.0, 0.0]
                .into_iter()
                .map(|d| {
                    [
                        (x as f64 + d).round() as u32,
                        (row as f64 + d).round() as u32,
                    ]
                })
                .find(|&[c, r]| {
                    (c == x && r == row || runs::contains(down, c, r))
                        && self
                            .near(c as f64, r as f64, l, self.s.min_apart_px)
                            .next()
                            .is_none()
                });
            match at {
                Some(col_row) => self.push(Point {
                    col_row,
                    layer: l,
                    island: false,
                }),
                // Too close to a point that does not cover it (spacing below the pillar
                // diameter): left to that point.
                None => x += 1,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spread() -> Spread {
        Spread {
            width: 200,
            cover_px: 10.0,
            min_apart_px: 5.0,
            reach_layers: 10,
            self_px: 1.0,
            contact_px: 2.0,
            first_on_pad: false,
            firm_hold: false,
        }
    }

    /// A disc of `radius` pixels about (`c`, `r`).
    fn disc(c: f64, r: f64, radius: f64) -> Vec<Run> {
        let mut out = Vec::new();
        for row in 0..200u32 {
            let dy = row as f64 + 0.5 - r;
            if dy.abs() < radius {
                let w = (radius * radius - dy * dy).sqrt();
                let (a, b) = ((c - w).round() as u32, (c + w).round() as u32);
                if b > a {
                    out.push([row, a, b]);
                }
            }
        }
        out
    }

    #[test]
    fn every_pixel_of_a_floating_disc_is_covered_and_points_stay_apart() {
        // A disc starting in mid-air at layer 3, then a column on it.
        let d = disc(100.0, 100.0, 40.0);
        let mut masks = vec![Vec::new(); 3];
        masks.extend(std::iter::repeat_n(d.clone(), 5));
        let s = spread();
        let pts = place(&masks, 3, &s);
        assert!(pts.iter().all(|p| p.layer == 3), "{pts:?}");
        assert_eq!(pts.iter().filter(|p| p.island).count(), 1);
        // The island's point is its centre.
        let centre = pts.iter().find(|p| p.island).unwrap().col_row;
        assert!((centre[0] as f64 - 100.0).abs() <= 1.0 && (centre[1] as f64 - 100.0).abs() <= 1.0);
        for &[row, a, b] in &d {
            for c in a..b {
                assert!(pts.iter().any(|p| {
                    let (dc, dr) = (
                        p.col_row[0] as f64 - c as f64,
                        p.col_row[1] as f64 - row as f64,
                    );
                    dc * dc + dr * dr <= 100.0
                }));
            }
        }
        for (i, p) in pts.iter().enumerate() {
            assert!(runs::contains(&d, p.col_row[0], p.col_row[1]));
            for q in &pts[i + 1..] {
                let (dc, dr) = (
                    p.col_row[0] as f64 - q.col_row[0] as f64,
                    p.col_row[1] as f64 - q.col_row[1] as f64,
                );
                assert!(dc * dc + dr * dr > 25.0, "{p:?} {q:?}");
            }
        }
        // A density near one per cover² (every pixel within the cover radius).
        let area = d.iter().map(|r| (r[2] - r[1]) as f64).sum::<f64>();
        assert!((pts.len() as f64) < 2.0 * area / 100.0, "{}", pts.len());
    }

    #[test]
    fn an_island_crowded_by_a_point_below_gets_its_point_deep_inside_not_at_its_edge() {
        // A small island at layer 3 (its point at its centre), then at layer 6 an island
        // whose centre lies within a pillar's diameter (5 px) of that point.
        let (a, b) = (disc(100.0, 100.0, 4.0), disc(102.0, 100.0, 10.0));
        let masks = vec![vec![], vec![], vec![], a, vec![], vec![], b.clone()];
        let pts = place(&masks, 3, &spread());
        let first = pts.iter().find(|p| p.layer == 3).unwrap().col_row;
        let p = pts
            .iter()
            .find(|p| p.layer == 6 && p.island)
            .unwrap()
            .col_row;
        let [c, r] = p.map(|v| v as f64);
        let [c0, r0] = first.map(|v| v as f64);
        assert!((c - c0).hypot(r - r0) > 5.0, "{pts:?}");
        // At least a head's contact (2 px) inside the island's edge (the first clear pixel
        // in scan order lay on it).
        assert!((c + 0.5 - 102.0).hypot(r + 0.5 - 100.0) <= 8.0, "{pts:?}");
        assert!(runs::contains(&b, p[0], p[1]));
    }

    #[test]
    fn a_steep_cone_needs_nothing_and_a_shallow_one_is_supported() {
        // Growing discs: 0.5 px per layer (steeper than the 1 px self-supporting step)
        // and 4 px per layer (an overhang).
        for (grow, needs) in [(0.5, false), (4.0, true)] {
            let masks: Vec<Vec<Run>> = (0..12)
                .map(|l| disc(100.0, 100.0, 20.0 + grow * l as f64))
                .collect();
            let s = Spread {
                first_on_pad: true,
                ..spread()
            };
            let pts = place(&masks, 0, &s);
            assert_eq!(!pts.is_empty(), needs, "grow {grow}: {pts:?}");
            assert!(pts.iter().all(|p| !p.island));
        }
    }

    #[test]
    fn a_region_touching_the_layer_below_in_two_pixels_is_an_island() {
        let base = vec![[10u32, 10, 12]];
        let top = vec![[10u32, 11, 30], [11, 11, 30]];
        let masks = vec![base.clone(), top];
        let pts = place(
            &masks,
            0,
            &Spread {
                first_on_pad: true,
                ..spread()
            },
        );
        assert!(pts.iter().any(|p| p.island && p.layer == 1), "{pts:?}");
    }

    #[test]
    fn a_part_hanging_by_a_thin_neck_over_nothing_gets_a_point_with_the_correction() {
        // A block on the layer below; beside it, over nothing, a square joined to it by a
        // neck one pixel wide (which the correction cuts).
        let below: Vec<Run> = (20..40).map(|r| [r, 20, 40]).collect();
        let mut top = below.clone();
        top.extend((20..40).map(|r| [r, 60, 80]));
        top.push([30, 40, 60]);
        top.sort_unstable();
        let top = runs::union(&top, &[]);
        let masks = vec![below, top];
        for firm_hold in [false, true] {
            let s = Spread {
                first_on_pad: true,
                firm_hold,
                ..spread()
            };
            let pts = place(&masks, 0, &s);
            let held = pts
                .iter()
                .any(|p| p.island && p.layer == 1 && (60..80).contains(&p.col_row[0]));
            assert_eq!(held, firm_hold, "firm hold {firm_hold}: {pts:?}");
        }
    }

    #[test]
    fn a_hold_two_pixels_wide_is_firm_only_without_the_correction() {
        // A block whose pixels overlap the layer below in a strip `w` pixels wide.
        let block: Vec<Run> = (20..40).map(|r| [r, 20, 60]).collect();
        for (w, firm) in [(2, false), (3, true)] {
            let below: Vec<Run> = (20..40).map(|r| [r, 60 - w, 80]).collect();
            let masks = vec![below, block.clone()];
            for firm_hold in [false, true] {
                let s = Spread {
                    first_on_pad: true,
                    firm_hold,
                    ..spread()
                };
                let island = place(&masks, 0, &s).iter().any(|p| p.island);
                assert_eq!(island, firm_hold && !firm, "{w} px, firm hold {firm_hold}");
            }
        }
        // A wall two pixels thin, shifted by a pixel from layer to layer: it holds as drawn.
        let wall = |c: u32| (20..40).map(|r| [r, c, c + 2]).collect::<Vec<Run>>();
        let s = Spread {
            first_on_pad: true,
            firm_hold: true,
            ..spread()
        };
        assert!(place(&[wall(30), wall(31), wall(32)], 0, &s).is_empty());
        assert!(!runs::has_interior(&[[5, 0, 10], [6, 0, 10]]));
        assert!(runs::has_interior(&[[5, 3, 4], [6, 0, 10], [7, 3, 5]]));
        assert!(!runs::has_interior(&[[5, 3, 4], [6, 0, 10], [8, 3, 5]]));
    }
}
