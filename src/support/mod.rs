//! Supports: points under every island and every surface that faces down too flat, a head,
//! pillar and foot for each, and a pad under them all, as one mesh the slicer cuts with
//! the part (docs/SUPPORTS.md).
//!
//! The search runs on the part's own lit pixels, layer by layer, as the job will draw them
//! (the same rasterizer, coverage ≥ 50 %): the part is cut and drawn once more before the
//! job, its pixels kept as runs. `points.rs` places the points, `columns.rs` finds what
//! each support stands on and its profile, `shapes.rs` makes the meshes, `runs.rs` holds
//! the pixel-set operations. The part is lifted by whole layers (the pad and the
//! elevation), so its sections are those of the job without supports, moved up.

mod columns;
mod points;
mod runs;
mod shapes;

pub use columns::{Column, Foot, Shape};

pub use shapes::SIDES;

use crate::mesh::Mesh;
use crate::profile::{Field, Supports};
use crate::raster::{Rasterizer, ScratchPool};
use crate::slice::Slicer;
use rayon::prelude::*;

/// Layers cut and drawn at a time by the search.
const WINDOW: usize = 64;
/// What the pad and the base cones keep clear of the field's edge, mm.
const EDGE_ROOM_MM: f64 = 1e-3;

/// The pad: its outlines and thickness.
#[derive(Debug, Clone, PartialEq)]
pub struct Pad {
    /// Thickness, mm (whole layers).
    pub thickness_mm: f64,
    /// Outline of its top, counter-clockwise, mm.
    pub top: Vec<[f64; 2]>,
    /// Outline of its bottom (on the platform), mm.
    pub bottom: Vec<[f64; 2]>,
}

impl Pad {
    /// Area of its top, mm².
    pub fn top_area_mm2(&self) -> f64 {
        crate::slice::signed_area(&self.top)
    }
}

/// The supports of a part.
#[derive(Debug, Clone)]
pub struct Generated {
    /// One per point, in the order placed (bottom up).
    pub columns: Vec<Column>,
    /// The pad under them.
    pub pad: Pad,
    /// The shapes they were made with.
    pub shape: Shape,
    /// The whole structure: one closed shell per support and the pad.
    pub mesh: Mesh,
}

impl Generated {
    /// Where a column's point is on the build plane, mm.
    pub fn point_mm(&self, c: &Column, field: &Field) -> [f64; 3] {
        let px = field.pixel_mm;
        let [col, row] = c.point.col_row;
        [
            (col as f64 + 0.5) * px,
            field.height_mm() - (row as f64 + 0.5) * px,
            c.point.layer as f64 * self.shape.layer_mm,
        ]
    }
}

/// Layers the part is lifted by: the pad's and the elevation's, each whole layers (at
/// least one for the pad).
pub fn lift_layers(s: &Supports, layer_mm: f64) -> usize {
    let pad = ((s.pad_thickness_mm / layer_mm).round() as usize).max(1);
    pad + (s.elevation_mm / layer_mm).round() as usize
}

/// The supports of `part` (placed and lifted by [`lift_layers`] = `first`; its sections
/// offset by `offset_mm`, [`Slicer::with_offset`]), sliced into `n` layers of `layer_mm` on
/// `field`, for a job whose cure correction moves edges in (`corrected`) or not. An error
/// (a message) when the pad does not fit the field.
pub fn generate(
    (part, offset_mm): (&Mesh, f64),
    field: Field,
    (layer_mm, n, first): (f64, usize, usize),
    (s, corrected): (&Supports, bool),
) -> Result<Generated, String> {
    let masks = part_pixels((part, offset_mm), field, layer_mm, n, first);
    let px = field.pixel_mm;
    let tan = s.critical_angle_deg.to_radians().tan();
    let cover_mm = s.spacing_mm / std::f64::consts::SQRT_2;
    let pad_layers = ((s.pad_thickness_mm / layer_mm).round() as usize).max(1);
    let spread = points::Spread {
        width: field.width_px,
        cover_px: cover_mm / px,
        min_apart_px: s.pillar_diameter_mm / px,
        reach_layers: (cover_mm * tan / layer_mm).ceil() as usize,
        self_px: layer_mm / tan / px,
        contact_px: s.head_front_diameter_mm / 2.0 / px,
        first_on_pad: first == pad_layers,
        firm_hold: corrected,
    };
    let shape = Shape {
        pixel_mm: px,
        layer_mm,
        contact_r: s.head_front_diameter_mm / 2.0,
        pillar_r: s.pillar_diameter_mm / 2.0,
        base_r: s.base_diameter_mm / 2.0,
        head_len: s.head_length_mm,
        penetration: s.head_penetration_mm,
        base_len: s.base_height_mm,
        pad_top: pad_layers as f64 * layer_mm,
        max_len: s.pillar_max_length_mm,
    };
    let pts = points::place(&masks, first, &spread);
    let columns: Vec<Column> = pts
        .par_iter()
        .map(|&p| columns::column(p, &masks, first, &shape))
        .collect();
    let mut g = Generated {
        columns,
        pad: Pad {
            thickness_mm: shape.pad_top,
            top: Vec::new(),
            bottom: Vec::new(),
        },
        shape,
        mesh: Mesh::from_soup(&[], "supports"),
    };
    // A base cone is narrowed to fit the field and to keep clear of its neighbours' (so
    // that no two shells overlap there), not below its pillar.
    let (w, h) = (field.width_mm(), field.height_mm());
    let on_pad: Vec<(usize, [f64; 3])> = (0..g.columns.len())
        .filter(|&i| g.columns[i].foot == Foot::Pad && g.columns[i].rings.len() > 1)
        .map(|i| (i, g.point_mm(&g.columns[i], &field)))
        .collect();
    for &(i, [x, y, _]) in &on_pad {
        let apart = on_pad
            .iter()
            .filter(|&&(j, _)| j != i)
            .map(|(_, q)| (q[0] - x).hypot(q[1] - y))
            .fold(f64::INFINITY, f64::min);
        let room = x.min(w - x).min(y).min(h - y) - EDGE_ROOM_MM;
        let c = &mut g.columns[i];
        c.rings[0][1] = c.rings[0][1].min(room).min(apart / 2.0).max(c.rings[1][1]);
    }
    let on_pad = spread.first_on_pad.then(|| masks[first].as_slice());
    g.pad = pad(&g, on_pad, field, s)?;
    let mut mesh = shapes::pad(&g.pad.bottom, &g.pad.top, shape.pad_top);
    for c in &g.columns {
        let [x, y, _] = g.point_mm(c, &field);
        mesh.append(&shapes::revolved(x, y, &c.rings));
    }
    g.mesh = mesh;
    Ok(g)
}

/// The part's lit pixels per layer (empty below `first`), as the job draws them.
fn part_pixels(
    (part, offset_mm): (&Mesh, f64),
    field: Field,
    layer_mm: f64,
    n: usize,
    first: usize,
) -> Vec<Vec<runs::Run>> {
    let raster = Rasterizer::new(field);
    let mut slicer = Slicer::new(part, layer_mm, n).with_offset(offset_mm);
    let mut masks = vec![Vec::new(); first.min(n)];
    // Each split of a window takes a scratch from the pool (rayon makes many).
    let pool = ScratchPool::default();
    let mut lo = first;
    while lo < n {
        let sections = slicer.window(lo..(lo + WINDOW).min(n));
        let drawn: Vec<Vec<runs::Run>> = sections
            .par_iter()
            .map_init(
                || pool.take(),
                |scratch, sec| {
                    scratch.record_runs = true;
                    let m = raster.coverage(&sec.contours, scratch);
                    scratch.recycle(m);
                    std::mem::take(&mut scratch.lit_runs.runs)
                },
            )
            .collect();
        masks.extend(drawn);
        lo += WINDOW;
    }
    masks
}

/// The pad under the columns that stand on it (and the part's first layer `on_pad`, when
/// it rests on the pad), or an error when it does not fit `field`.
fn pad(
    g: &Generated,
    on_pad: Option<&[runs::Run]>,
    field: Field,
    s: &Supports,
) -> Result<Pad, String> {
    let px = field.pixel_mm;
    let mut pts: Vec<[f64; 2]> = Vec::new();
    for c in g.columns.iter().filter(|c| c.foot == Foot::Pad) {
        let [x, y, _] = g.point_mm(c, &field);
        let r = c.rings[0][1];
        pts.extend((0..SIDES).map(|i| {
            let a = std::f64::consts::TAU * i as f64 / SIDES as f64;
            [x + r * a.cos(), y + r * a.sin()]
        }));
    }
    for &[row, a, b] in on_pad.unwrap_or(&[]) {
        let (y0, y1) = (
            field.height_mm() - (row + 1) as f64 * px,
            field.height_mm() - row as f64 * px,
        );
        for x in [a as f64 * px, b as f64 * px] {
            pts.extend([[x, y0], [x, y1]]);
        }
    }
    let hull = shapes::convex_hull(&pts);
    if hull.is_empty() {
        return Err("nothing to stand on the pad".into());
    }
    let slope = s.pad_wall_slope_deg.to_radians();
    let out = if s.pad_wall_slope_deg >= 90.0 {
        0.0
    } else {
        g.shape.pad_top / slope.tan()
    };
    // By the field's edge the margin and the slope narrow to what fits.
    let (w, h) = (field.width_mm(), field.height_mm());
    let room = hull
        .iter()
        .map(|p| p[0].min(w - p[0]).min(p[1]).min(h - p[1]))
        .fold(f64::INFINITY, f64::min)
        - EDGE_ROOM_MM;
    let top = s.pad_margin_mm.max(px / 2.0).min(room).max(EDGE_ROOM_MM);
    let pad = Pad {
        thickness_mm: g.shape.pad_top,
        top: shapes::offset(&hull, top),
        bottom: shapes::offset(&hull, (s.pad_margin_mm + out).min(room).max(top)),
    };
    let lo = pad
        .bottom
        .iter()
        .fold([f64::INFINITY; 2], |a, p| [a[0].min(p[0]), a[1].min(p[1])]);
    let hi = pad.bottom.iter().fold([f64::NEG_INFINITY; 2], |a, p| {
        [a[0].max(p[0]), a[1].max(p[1])]
    });
    let beyond = (-lo[0]).max(-lo[1]).max(hi[0] - w).max(hi[1] - h);
    if beyond > 1e-9 {
        return Err(format!(
            "the supports' pad spans x {:.3}..{:.3}, y {:.3}..{:.3} mm, {:.3} mm beyond the build field 0..{w:.3} x 0..{h:.3} mm: the part's supports stand too close to its edge; move the part in (--position) or turn it",
            lo[0], hi[0], lo[1], hi[1], beyond
        ));
    }
    Ok(pad)
}
