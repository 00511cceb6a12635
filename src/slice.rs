//! Slicing: cuts a welded mesh with the layer planes and chains the cut segments into
//! closed, oriented contours.
//!
//! Layer `i` of height `h` is cut by the plane `z = (i + 0.5)·h`; a partial top layer is
//! dropped (PrusaSlicer's rule). A vertex is "below" a plane when `z <= Z`, "above" when
//! `z > Z` (the solid is the half-open slab `z_min <= Z < z_max`): a vertex on a plane
//! gives no duplicate or missing point, a bottom face on a plane is part of the section and
//! a top face on a plane is not.
//!
//! A triangle straddling a plane gives one segment from the point on its "down" edge
//! (above→below in its winding) to the point on its "up" edge, so outer contours run
//! counter-clockwise seen from +Z. End points are identified by mesh edge ids and chained
//! through them, never through rounded coordinates; each is computed from its edge's end
//! points in vertex id order, so the two triangles of an edge agree bit for bit.
//!
//! ## Repair rule for broken meshes
//! 1. A flipped facet's segment is still chained through its edge ids; each closed loop
//!    takes the orientation most of its segments agree with.
//! 2. Open chains (holes in the surface) are repaired greedily: a chain's end is joined to
//!    the nearest end of another open chain within [`MAX_GAP_MM`] and nearer than its own
//!    start; otherwise it is closed by a straight edge back to its start, unless that edge
//!    is longer than [`MAX_GAP_MM`] and crosses another contour of the layer (or the chain
//!    itself). Such chains are dropped, as are chains of fewer than three points or no
//!    area; joined, closed and dropped chains are counted in [`SliceStats`] and reported.
//! 3. The sections are filled with the nonzero winding rule, so overlapping and touching
//!    shells union.

pub mod offset;

use crate::mesh::Mesh;
use rayon::prelude::*;

/// Largest gap, mm, closed between the ends of open chains (see the module docs).
pub const MAX_GAP_MM: f64 = 2.0;

/// A closed contour: points in order, the closing edge implied. Counter-clockwise
/// (seen from +Z, x right, y up) for outer boundaries, clockwise for holes.
pub type Contour = Vec<[f64; 2]>;

/// The section of one layer.
#[derive(Debug, Clone, Default)]
pub struct Section {
    /// Closed contours.
    pub contours: Vec<Contour>,
    /// Contours closed from open chains (repair rule 2).
    pub joined_chains: u32,
    /// Open chains that were dropped (repair rule 2).
    pub dropped_chains: u32,
    /// With support shells in the layer ([`Slicer::with_supports_from`]): the area of the
    /// part's own contours, mm² (the supports add the rest of the layer's lit area).
    pub part_area_mm2: Option<f64>,
}

/// Repair counts over the whole job.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SliceStats {
    /// Layers that needed any repair.
    pub repaired_layers: u32,
    /// Open chains closed by joining.
    pub joined_chains: u32,
    /// Open chains dropped.
    pub dropped_chains: u32,
}

/// Height of the cutting plane of layer `i`.
#[inline]
pub fn plane_z(i: usize, h: f64) -> f64 {
    (i as f64 + 0.5) * h
}

/// Number of layers of a part whose top is at `z_max` (partial top layer dropped), or
/// `None` when that count is beyond what an `f64` division can give exactly (a far-off
/// vertex, a vanishing layer height).
pub fn layer_count(z_max: f64, h: f64) -> Option<usize> {
    if z_max <= 0.0 {
        return Some(0);
    }
    let q = (z_max / h).floor();
    // Counts beyond 2^52 have no exact f64 neighbours to step between (and no machine
    // prints them): say so instead of saturating or wrapping.
    if q.is_nan() || q >= (1u64 << 52) as f64 {
        return None;
    }
    let mut n = q as usize;
    // Guard against floating error in the division.
    while n > 0 && (n as f64) * h > z_max + 1e-12 {
        n -= 1;
    }
    while ((n + 1) as f64) * h <= z_max {
        n += 1;
    }
    Some(n)
}

#[derive(Clone, Copy, Debug)]
struct Seg {
    from_edge: u32,
    to_edge: u32,
    p: [f64; 2],
    q: [f64; 2],
}

/// Streams a mesh's sections window by window, so memory depends on the window size,
/// not on the number of layers.
///
/// Triangles are sorted by their lowest z once; [`Slicer::window`] (called with increasing
/// layer ranges) keeps the triangles that can reach the window active, cuts them in
/// parallel and chains each layer in parallel. The result does not depend on the window
/// size or the thread count.
pub struct Slicer<'m> {
    mesh: &'m Mesh,
    h: f64,
    n: usize,
    zmin: Vec<f64>,
    zmax: Vec<f64>,
    order: Vec<u32>,
    next: usize,
    active: Vec<u32>,
    /// The lowest plane of the previous window.
    z_lo: f64,
    /// Repair counts over the windows sliced so far.
    pub stats: SliceStats,
    /// Edges from this id on belong to support shells.
    support_edges: u32,
    /// The part's contours are offset by this, mm ([`Slicer::with_offset`]).
    offset_mm: f64,
    /// The layers cut, when not all ([`Slicer::only`]).
    wanted: Option<Vec<bool>>,
}

impl<'m> Slicer<'m> {
    /// Prepares to slice `mesh` (already placed) into `n` layers of height `h`.
    pub fn new(mesh: &'m Mesh, h: f64, n: usize) -> Self {
        let (zmin, zmax): (Vec<f64>, Vec<f64>) = mesh
            .triangles
            .par_iter()
            .map(|t| {
                let z = [
                    mesh.vertices[t[0] as usize][2],
                    mesh.vertices[t[1] as usize][2],
                    mesh.vertices[t[2] as usize][2],
                ];
                (z[0].min(z[1]).min(z[2]), z[0].max(z[1]).max(z[2]))
            })
            .unzip();
        let mut order: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
        // A total order (ties by index): the same result at any thread count.
        order.par_sort_unstable_by(|&a, &b| {
            zmin[a as usize]
                .total_cmp(&zmin[b as usize])
                .then(a.cmp(&b))
        });
        Slicer {
            mesh,
            h,
            n,
            zmin,
            zmax,
            order,
            next: 0,
            active: Vec::new(),
            z_lo: f64::NEG_INFINITY,
            stats: SliceStats::default(),
            support_edges: u32::MAX,
            offset_mm: 0.0,
            wanted: None,
        }
    }

    /// The same slicer, counting the contours of the edges from `edge` on (the shells
    /// appended after the part: supports, whose shells share no edge with it) as support
    /// ([`Section::part_area_mm2`]).
    pub fn with_supports_from(mut self, edge: Option<u32>) -> Self {
        self.support_edges = edge.unwrap_or(u32::MAX);
        self
    }

    /// The same slicer, offsetting the part's contours of every section by `d_mm` along
    /// their outward normals ([`offset::offset`]; the dimensional correction's
    /// `xy_offset_mm`); support contours are not offset.
    pub fn with_offset(mut self, d_mm: f64) -> Self {
        self.offset_mm = d_mm;
        self
    }

    /// Cuts only the layers `wanted` holds true for (indexed by layer); the others come
    /// back empty and count no repairs (a job made again needs only the sections around
    /// the layers it draws again).
    pub fn only(mut self, wanted: Vec<bool>) -> Self {
        self.wanted = Some(wanted);
        self
    }

    /// Sections of layers `range`: cheapest after the previous call's range (a range
    /// below it finds the active triangles again from the lowest).
    pub fn window(&mut self, range: std::ops::Range<usize>) -> Vec<Section> {
        let range = range.start..range.end.min(self.n);
        if range.is_empty() {
            return Vec::new();
        }
        let z_lo = plane_z(range.start, self.h);
        let z_hi = plane_z(range.end - 1, self.h);
        if z_lo < self.z_lo {
            // Below the previous range: triangles it dropped may reach this one.
            self.next = 0;
            self.active.clear();
        }
        self.z_lo = z_lo;
        while self.next < self.order.len() && self.zmin[self.order[self.next] as usize] <= z_hi {
            self.active.push(self.order[self.next]);
            self.next += 1;
        }
        let zmax = &self.zmax;
        self.active.retain(|&t| zmax[t as usize] > z_lo);

        let (mesh, h, wanted) = (self.mesh, self.h, self.wanted.as_deref());
        let chunk = 4096;
        let parts: Vec<Vec<(u32, Seg)>> = self
            .active
            .par_chunks(chunk)
            .map(|tris| {
                // A triangle is cut by a few planes of a window: room for four each.
                let mut out = Vec::with_capacity(4 * tris.len());
                for &ti in tris {
                    let ti = ti as usize;
                    let t = &mesh.triangles[ti];
                    let v = [
                        mesh.vertices[t[0] as usize],
                        mesh.vertices[t[1] as usize],
                        mesh.vertices[t[2] as usize],
                    ];
                    let (zmin, zmax) = (self.zmin[ti], self.zmax[ti]);
                    // Planes with zmin <= Z < zmax; candidate range padded, then tested exactly.
                    let lo = ((zmin / h - 0.5).floor().max(0.0) as usize).max(range.start);
                    let hi = ((zmax / h - 0.5).ceil().max(-1.0) + 1.0) as usize;
                    for i in lo..hi.min(range.end) {
                        let z = plane_z(i, h);
                        if !(zmin <= z && zmax > z) || wanted.is_some_and(|w| !w[i]) {
                            continue;
                        }
                        if let Some(s) = cut_triangle(mesh, ti, t, &v, z) {
                            out.push(((i - range.start) as u32, s));
                        }
                    }
                }
                out
            })
            .collect();
        // Each layer's segments, its list sized first.
        let mut count = vec![0usize; range.len()];
        for (i, _) in parts.iter().flatten() {
            count[*i as usize] += 1;
        }
        let mut segs: Vec<Vec<Seg>> = count.into_iter().map(Vec::with_capacity).collect();
        for part in parts {
            for (i, s) in part {
                segs[i as usize].push(s);
            }
        }
        let (support, d) = (self.support_edges, self.offset_mm);
        let sections: Vec<Section> = (segs.par_iter().enumerate())
            .map(|(k, s)| match wanted {
                Some(w) if !w[range.start + k] => Section::default(),
                _ => chain(s, support, d),
            })
            .collect();
        for s in &sections {
            if s.joined_chains + s.dropped_chains > 0 {
                self.stats.repaired_layers += 1;
            }
            self.stats.joined_chains += s.joined_chains;
            self.stats.dropped_chains += s.dropped_chains;
        }
        sections
    }
}

fn cut_triangle(mesh: &Mesh, ti: usize, t: &[u32; 3], v: &[[f64; 3]; 3], z: f64) -> Option<Seg> {
    let above = [v[0][2] > z, v[1][2] > z, v[2][2] > z];
    let mut down = None; // edge k from above to below
    let mut up = None; // edge k from below to above
    for k in 0..3 {
        let a = above[k];
        let b = above[(k + 1) % 3];
        if a && !b {
            down = Some(k);
        } else if !a && b {
            up = Some(k);
        }
    }
    let (d, u) = (down?, up?);
    let point = |k: usize| -> [f64; 2] {
        // Canonical order by vertex id so both triangles sharing the edge agree exactly.
        let (i, j) = (t[k], t[(k + 1) % 3]);
        let (i, j) = if i < j { (i, j) } else { (j, i) };
        let a = mesh.vertices[i as usize];
        let b = mesh.vertices[j as usize];
        let s = (z - a[2]) / (b[2] - a[2]);
        [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])]
    };
    let te = mesh.tri_edges[ti];
    Some(Seg {
        from_edge: te[d],
        to_edge: te[u],
        p: point(d),
        q: point(u),
    })
}

/// Chains one layer's segments into closed contours (see the module docs for the rule);
/// the closed contours of edges from `support` on are counted as support. The part's
/// contours are then offset by `offset_mm` ([`offset::offset`]).
fn chain(segs: &[Seg], support: u32, offset_mm: f64) -> Section {
    SEG_OF_EDGE.with(|slots| chain_with(segs, support, offset_mm, &mut slots.borrow_mut()))
}

thread_local! {
    /// Per mesh edge, the segments starting and ending at it ([`chain_with`]); every entry
    /// is `NONE` between layers.
    static SEG_OF_EDGE: std::cell::RefCell<Vec<[u32; 2]>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// No segment.
const NONE: u32 = u32::MAX;

/// The segments leaving each edge, in order of edge then segment: by edge index in `slots`
/// when no edge starts (or ends) two segments, as in a closed mesh (entries put back to
/// [`NONE`] afterwards), else from sorted tables. The first unused one is the same either
/// way.
enum SegsAtEdge<'a> {
    Slots(&'a mut Vec<[u32; 2]>),
    Sorted([Vec<(u32, u32)>; 2]),
}

impl SegsAtEdge<'_> {
    /// The first unused segment starting (`end` 0) or ending (1) at edge `e`.
    fn find(&self, end: usize, used: &[bool], e: u32) -> Option<u32> {
        match self {
            SegsAtEdge::Slots(slots) => {
                let s = slots[e as usize][end];
                (s != NONE && !used[s as usize]).then_some(s)
            }
            SegsAtEdge::Sorted(tabs) => {
                let tab = &tabs[end];
                let k = tab.partition_point(|&(x, _)| x < e);
                tab[k..]
                    .iter()
                    .take_while(|&&(x, _)| x == e)
                    .find(|&&(_, s)| !used[s as usize])
                    .map(|&(_, s)| s)
            }
        }
    }
}

/// Puts the entries of `segs`' edges in `slots` back to [`NONE`].
fn clear_slots(slots: &mut [[u32; 2]], segs: &[Seg]) {
    for s in segs {
        slots[s.from_edge as usize] = [NONE; 2];
        slots[s.to_edge as usize] = [NONE; 2];
    }
}

/// [`chain`] with the thread's per-edge table `slots`.
fn chain_with(segs: &[Seg], support: u32, offset_mm: f64, slots: &mut Vec<[u32; 2]>) -> Section {
    let n = segs.len();
    let top = segs
        .iter()
        .map(|s| s.from_edge.max(s.to_edge) as usize + 1)
        .max();
    if slots.len() < top.unwrap_or(0) {
        slots.resize(top.unwrap_or(0), [NONE; 2]);
    }
    let mut unique = true;
    for (i, s) in segs.iter().enumerate() {
        for (end, e) in [(0, s.from_edge), (1, s.to_edge)] {
            let slot = &mut slots[e as usize][end];
            unique &= *slot == NONE;
            *slot = i as u32;
        }
    }
    let at_edge = if unique {
        SegsAtEdge::Slots(slots)
    } else {
        clear_slots(slots, segs);
        let table = |edge: fn(&Seg) -> u32| {
            let mut t: Vec<(u32, u32)> = (segs.iter().enumerate())
                .map(|(i, s)| (edge(s), i as u32))
                .collect();
            t.sort_unstable();
            t
        };
        SegsAtEdge::Sorted([table(|s| s.from_edge), table(|s| s.to_edge)])
    };
    let mut used = vec![false; n];
    // The next segment of a chain at `node`, marked used: one leaving it the way the
    // chain runs (`fwd`: from its start edge), else one leaving it the other way (a
    // flipped facet). Its other end's point and edge, and its vote for the orientation.
    let step = |node: u32, fwd: bool, used: &mut [bool]| {
        for from_start in [fwd, !fwd] {
            if let Some(s) = at_edge.find(!from_start as usize, used, node) {
                used[s as usize] = true;
                let sg = segs[s as usize];
                let vote = if from_start == fwd { 1 } else { -1 };
                return Some(if from_start {
                    (sg.q, sg.to_edge, vote)
                } else {
                    (sg.p, sg.from_edge, vote)
                });
            }
        }
        None
    };

    let mut section = Section::default();
    let mut open: Vec<Contour> = Vec::new();
    // Support contours go after the part's: an open chain of the part is closed or dropped
    // as it would be without them.
    let mut supports: Vec<Contour> = Vec::new();
    for s0 in 0..n {
        if used[s0] {
            continue;
        }
        used[s0] = true;
        let first = segs[s0];
        let start_node = first.from_edge;
        let mut pts = vec![first.p, first.q];
        let mut agree: i64 = 1;
        let mut node = first.to_edge;
        let mut closed = node == start_node;
        while !closed {
            let Some((p, next, vote)) = step(node, true, &mut used) else {
                break;
            };
            pts.push(p);
            (node, agree) = (next, agree + vote);
            closed = node == start_node;
        }
        if closed {
            pts.pop(); // last point equals the first
            finish_loop(&mut pts, agree < 0);
            if pts.len() >= 3 {
                if start_node >= support {
                    supports.push(pts);
                } else {
                    section.contours.push(pts);
                }
            }
            continue;
        }
        // Open: extend backwards from the start node too.
        let mut back: Vec<[f64; 2]> = Vec::new();
        let mut node = start_node;
        while let Some((p, next, vote)) = step(node, false, &mut used) {
            back.push(p);
            (node, agree) = (next, agree + vote);
        }
        back.reverse();
        back.extend(pts);
        let mut chain = back;
        if agree < 0 {
            chain.reverse();
        }
        open.push(chain);
    }
    if let SegsAtEdge::Slots(slots) = at_edge {
        clear_slots(slots, segs);
    }
    if !open.is_empty() {
        join_open(open, &mut section);
    }
    if offset_mm != 0.0 {
        section.contours = offset::offset(&section.contours, offset_mm);
    }
    if !supports.is_empty() {
        section.part_area_mm2 = Some(section.contours.iter().map(signed_area).sum());
        let supports = orient_supports(&section.contours, supports);
        section.contours.extend(supports);
    }
    section
}

/// Gives each support contour the winding that keeps it lit wherever it overlaps the part
/// under the nonzero rule. A region of the part whose contours run backwards (a defective
/// mesh) has winding −1, and a counter-clockwise support over it would cancel it there. The
/// part's winding is sampled at the support's centre, at its vertices and half-way between:
/// all of them ≥ 0 keeps the support counter-clockwise, all ≤ 0 turns it, and a support over
/// both signs is doubled (winding 2, so that the sum with the part's −1, 0 or +1 is never 0).
/// Returns the supports to append to the layer's contours.
fn orient_supports(part: &[Contour], supports: Vec<Contour>) -> Vec<Contour> {
    if part.is_empty() {
        return supports;
    }
    // The part's edges in bands of y, for the crossing counts.
    let (lo, hi) = part
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
            (a.0.min(p[1]), a.1.max(p[1]))
        });
    const BANDS: usize = 64;
    let step = ((hi - lo) / BANDS as f64).max(1e-9);
    let band = |y: f64| (((y - lo) / step).floor().max(0.0) as usize).min(BANDS - 1);
    let mut bands: Vec<Vec<([f64; 2], [f64; 2])>> = vec![Vec::new(); BANDS];
    for c in part {
        for i in 0..c.len() {
            let (a, b) = (c[i], c[(i + 1) % c.len()]);
            for edges in &mut bands[band(a[1].min(b[1]))..=band(a[1].max(b[1]))] {
                edges.push((a, b));
            }
        }
    }
    // Winding number of the part at (x, y): edges crossing the ray to the right.
    let winding = |[x, y]: [f64; 2]| {
        if y < lo || y > hi {
            return 0;
        }
        let mut w = 0i32;
        for &(a, b) in &bands[band(y)] {
            if (a[1] <= y) != (b[1] <= y) {
                let t = (y - a[1]) / (b[1] - a[1]);
                if a[0] + t * (b[0] - a[0]) > x {
                    w += if b[1] > a[1] { 1 } else { -1 };
                }
            }
        }
        w
    };
    let mut out = Vec::with_capacity(supports.len());
    for mut c in supports {
        let n = c.len() as f64;
        let centre = c
            .iter()
            .fold([0.0; 2], |s, p| [s[0] + p[0] / n, s[1] + p[1] / n]);
        let samples = std::iter::once(centre).chain(
            c.iter()
                .flat_map(|p| [*p, [(p[0] + centre[0]) / 2.0, (p[1] + centre[1]) / 2.0]]),
        );
        let (mut neg, mut pos) = (false, false);
        for w in samples.map(winding) {
            neg |= w < 0;
            pos |= w > 0;
        }
        if neg && pos {
            out.push(c.clone());
        } else if neg {
            c.reverse();
        }
        out.push(c);
    }
    out
}

fn finish_loop(pts: &mut Contour, reverse: bool) {
    pts.dedup();
    while pts.len() > 1 && pts.first() == pts.last() {
        pts.pop();
    }
    if reverse {
        pts.reverse();
    }
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// Repair rule 2: join open chains end-to-start by nearest distance within MAX_GAP_MM.
fn join_open(mut open: Vec<Contour>, section: &mut Section) {
    let max2 = MAX_GAP_MM * MAX_GAP_MM;
    let mut alive = vec![true; open.len()];
    for i in 0..open.len() {
        if !alive[i] {
            continue;
        }
        loop {
            let end = *open[i].last().unwrap();
            // Candidates: own start, other chains' starts (appended), other chains' ends
            // (appended reversed: a flipped piece).
            let mut best = (dist2(end, open[i][0]), i, false);
            for (j, c) in open.iter().enumerate() {
                if j == i || !alive[j] {
                    continue;
                }
                for (d, rev) in [
                    (dist2(end, c[0]), false),
                    (dist2(end, *c.last().unwrap()), true),
                ] {
                    if d <= max2 && d < best.0 {
                        best = (d, j, rev);
                    }
                }
            }
            let (d2, j, rev) = best;
            if j != i {
                let mut other = std::mem::take(&mut open[j]);
                alive[j] = false;
                if rev {
                    other.reverse();
                }
                open[i].extend(other);
                continue;
            }
            let crossing = d2 > max2 && closing_edge_crosses(&open, &alive, i, &section.contours);
            let mut pts = std::mem::take(&mut open[i]);
            finish_loop(&mut pts, false);
            alive[i] = false;
            if !crossing && pts.len() >= 3 && signed_area(&pts).abs() > 1e-12 {
                section.contours.push(pts);
                section.joined_chains += 1;
            } else {
                section.dropped_chains += 1;
            }
            break;
        }
    }
}

/// True if the straight edge that would close open chain `i` (its end back to its start)
/// properly crosses any other contour or chain of the layer, or chain `i` itself.
fn closing_edge_crosses(open: &[Contour], alive: &[bool], i: usize, closed: &[Contour]) -> bool {
    let a = *open[i].last().unwrap();
    let b = open[i][0];
    let crosses_poly = |c: &Contour, closed_loop: bool, skip_ends: bool| {
        let n = c.len();
        let m = if closed_loop { n } else { n.saturating_sub(1) };
        (0..m).any(|k| {
            if skip_ends && (k == 0 || k + 1 == m) {
                return false;
            }
            segments_cross(a, b, c[k], c[(k + 1) % n])
        })
    };
    closed.iter().any(|c| crosses_poly(c, true, false))
        || open
            .iter()
            .enumerate()
            .any(|(j, c)| j != i && alive[j] && crosses_poly(c, false, false))
        || crosses_poly(&open[i], false, true)
}

/// Proper crossing of segments ab and cd (touching at an end point does not count).
fn segments_cross(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let orient = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
    };
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    o1 * o2 < 0.0 && o3 * o4 < 0.0
}

/// Slices `mesh` (already placed on the build plane) into `n` layers of height `h` at
/// once (tests and small jobs; the pipeline streams with [`Slicer`]).
#[cfg(any(test, feature = "internals"))]
pub fn slice(mesh: &Mesh, h: f64, n: usize) -> (Vec<Section>, SliceStats) {
    let mut s = Slicer::new(mesh, h, n);
    let sections = s.window(0..n);
    (sections, s.stats)
}

/// The box [x0, y0, x1, y1] of the points of `contours`, mm (x0 > x1 without points).
pub fn bounds<'a>(contours: impl IntoIterator<Item = &'a Contour>) -> [f64; 4] {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in contours.into_iter().flatten() {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    [lo[0], lo[1], hi[0], hi[1]]
}

/// Signed area of a contour (positive when counter-clockwise).
pub fn signed_area(c: &Contour) -> f64 {
    let mut a = 0.0;
    for i in 0..c.len() {
        let p = c[i];
        let q = c[(i + 1) % c.len()];
        a += p[0] * q[1] - q[0] * p[1];
    }
    a * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;

    use crate::mesh::cube_soup as cube;

    #[test]
    fn layer_count_rule() {
        assert_eq!(layer_count(25.0, 0.05), Some(500));
        assert_eq!(layer_count(0.049, 0.05), Some(0));
        assert_eq!(layer_count(0.1, 0.05), Some(2));
        assert_eq!(layer_count(0.12, 0.05), Some(2));
        // Counts no f64 can step through are refused, never saturated or wrapped.
        assert_eq!(layer_count(1e20, 1.0), None);
        assert_eq!(layer_count(10.0, 1e-300), None);
        assert_eq!(layer_count(f64::INFINITY, 1.0), None);
    }

    #[test]
    fn cube_sections_are_ccw_squares() {
        let m = Mesh::from_soup(&cube(10.0, [0.0; 3]), "t");
        let (secs, st) = slice(&m, 0.5, 20);
        assert_eq!(st, SliceStats::default());
        assert_eq!(secs.len(), 20);
        for s in &secs {
            assert_eq!(s.contours.len(), 1);
            assert!((signed_area(&s.contours[0]) - 100.0).abs() < 1e-9);
        }
    }

    #[test]
    fn plane_through_vertices_and_flat_faces() {
        // Cube from z=0.25 to z=1.25 with h = 0.5: planes at 0.25 (bottom face on the plane:
        // part of the section), 0.75, 1.25 (top face on the plane: not part of it).
        let m = Mesh::from_soup(&cube(1.0, [0.0, 0.0, 0.25]), "t");
        let (secs, _) = slice(&m, 0.5, 3);
        assert_eq!(secs[0].contours.len(), 1);
        assert!((signed_area(&secs[0].contours[0]) - 1.0).abs() < 1e-12);
        assert_eq!(secs[1].contours.len(), 1);
        assert!(secs[2].contours.is_empty());
    }

    #[test]
    fn flipped_facet_and_hole_are_repaired() {
        let mut s = cube(10.0, [0.0; 3]);
        let t = s[6];
        s[6] = [t[0], t[2], t[1]]; // flip a side facet
        s.remove(10); // punch a hole in another side
        let m = Mesh::from_soup(&s, "t");
        let (secs, st) = slice(&m, 1.0, 10);
        assert!(st.joined_chains > 0);
        assert_eq!(st.dropped_chains, 0);
        for s in &secs {
            assert_eq!(s.contours.len(), 1);
            assert!(
                (signed_area(&s.contours[0]) - 100.0).abs() < 1e-9,
                "{:?}",
                s.contours
            );
        }
    }

    #[test]
    fn open_chain_closing_across_another_contour_is_dropped() {
        // A U-shaped open chain whose mouth (x = 0..10 at y = 0) is 10 mm wide.
        let u: Contour = vec![[0.0, 0.0], [0.0, 10.0], [10.0, 10.0], [10.0, 0.0]];
        // Nothing in the way: closed into the square.
        let mut s = Section::default();
        join_open(vec![u.clone()], &mut s);
        assert_eq!(
            (s.contours.len(), s.joined_chains, s.dropped_chains),
            (1, 1, 0)
        );
        // A closed contour straddling the mouth: closing would cut through it, so dropped.
        let mut s = Section {
            contours: vec![vec![[4.0, -1.0], [6.0, -1.0], [6.0, 1.0], [4.0, 1.0]]],
            ..Section::default()
        };
        join_open(vec![u], &mut s);
        assert_eq!(
            (s.contours.len(), s.joined_chains, s.dropped_chains),
            (1, 0, 1)
        );
    }

    #[test]
    fn supports_stay_lit_over_backwards_regions() {
        let square = |x0: f64, x1: f64| vec![[x0, 0.0], [x1, 0.0], [x1, 2.0], [x0, 2.0]];
        let mut backwards = square(0.0, 2.0);
        backwards.reverse();
        // A backwards square (winding −1) beside a proper one (+1).
        let part = vec![backwards, square(2.0, 4.0)];
        let supports = vec![
            square(-0.5, 0.5), // over −1 and 0: turned
            square(3.0, 3.5),  // over +1: kept
            square(1.5, 2.5),  // over −1 and +1: doubled
            square(5.0, 6.0),  // beside the part: kept
        ];
        let out = orient_supports(&part, supports.clone());
        let mut turned = supports[0].clone();
        turned.reverse();
        let want = [
            turned,
            supports[1].clone(),
            supports[2].clone(),
            supports[2].clone(),
            supports[3].clone(),
        ];
        assert_eq!(out, want);
    }

    #[test]
    fn windows_give_the_same_sections() {
        let mut soup = cube(10.0, [0.0; 3]);
        soup.extend(cube(3.0, [20.0, 0.0, 4.0]));
        let m = Mesh::from_soup(&soup, "t");
        let (all, _) = slice(&m, 0.25, 40);
        let mut s = Slicer::new(&m, 0.25, 40);
        let mut win = Vec::new();
        for a in (0..40).step_by(7) {
            win.extend(s.window(a..a + 7));
        }
        assert_eq!(all.len(), win.len());
        for (x, y) in all.iter().zip(&win) {
            assert_eq!(x.contours, y.contours);
        }
        // From the top down, as the cure prediction cuts them.
        for a in (0..40).step_by(7).rev() {
            for (k, y) in s.window(a..a + 7).iter().enumerate() {
                assert_eq!(all[a + k].contours, y.contours, "layer {}", a + k);
            }
        }
    }

    #[test]
    fn only_the_wanted_layers_are_cut_and_counted() {
        // A cube with a hole in one side: every layer is repaired.
        let mut soup = cube(10.0, [0.0; 3]);
        soup.remove(10);
        let m = Mesh::from_soup(&soup, "t");
        let (all, stats) = slice(&m, 1.0, 10);
        assert_eq!(stats.repaired_layers, 10);
        let wanted: Vec<bool> = (0..10).map(|i| i % 3 == 1).collect();
        let mut s = Slicer::new(&m, 1.0, 10).only(wanted.clone());
        let some: Vec<Section> = [0..4, 4..10]
            .into_iter()
            .flat_map(|r| s.window(r))
            .collect();
        for (i, (a, b)) in all.iter().zip(&some).enumerate() {
            match wanted[i] {
                true => assert_eq!(a.contours, b.contours, "layer {i}"),
                false => assert!(b.contours.is_empty(), "layer {i}"),
            }
        }
        assert_eq!(s.stats.repaired_layers, 3);
    }
}
