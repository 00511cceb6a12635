//! A shaded picture of the part as the masks build it (and the thumbnail a bundle can
//! carry): the lit pixels of about [`Z_SLABS`] layers, shrunk to about [`XY_CELLS`] cells
//! across, stacked into voxels whose surface normals come from their lit neighbours, and
//! drawn from the front right, above, with a depth buffer.

use super::field::{layer_cells, part_crop};
use crate::bundle::BundleSource;
use crate::bundle::Manifest;
use crate::error::Result;
use crate::plot::Canvas;
use image::RgbImage;
use rayon::prelude::*;

/// Voxels across the longer side of the part's footprint.
pub const XY_CELLS: u32 = 220;
/// The most slabs of layers (each read from one layer's masks).
pub const Z_SLABS: usize = 220;
/// Turn of the view about the vertical axis from straight ahead, degrees (the camera is
/// to the front right).
const YAW_DEG: f64 = 35.0;
/// Height of the view above the build plane, degrees.
const PITCH_DEG: f64 = 30.0;
/// Reach of the normals' neighbourhood across the layers (x and y), voxels each way.
const NORMAL_RADIUS: i64 = 3;
/// Reach of the normals' neighbourhood up and down, slabs each way.
const NORMAL_RADIUS_Z: i64 = 1;
/// Background.
const BACKGROUND: [u8; 3] = [246, 246, 246];
/// The build plate under the part.
const PLATE: [u8; 3] = [222, 224, 228];
/// Lines on the build plate (every 10 mm) and its edge.
const PLATE_LINE: [u8; 3] = [196, 199, 206];
/// Colour of the part before shading.
const PART: [u8; 3] = [120, 165, 225];

/// A vector in build-plane mm: x right, y back (away from the viewer), z up.
type V3 = [f64; 3];

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalized(a: V3) -> V3 {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        [a[0] / n, a[1] / n, a[2] / n]
    } else {
        a
    }
}

/// The camera: screen right, screen up and the direction towards the viewer.
struct View {
    right: V3,
    up: V3,
    toward: V3,
}

impl View {
    fn new() -> View {
        let (t, p) = (YAW_DEG.to_radians(), PITCH_DEG.to_radians());
        View {
            right: [t.cos(), t.sin(), 0.0],
            up: [-t.sin() * p.sin(), t.cos() * p.sin(), p.cos()],
            toward: [t.sin() * p.cos(), -t.cos() * p.cos(), p.sin()],
        }
    }
}

/// The stacked layers as voxels: `nx` × `ny` × `nz`, x right, y back, z up.
struct Voxels {
    nx: usize,
    ny: usize,
    nz: usize,
    /// 1 where lit, x fastest, then y, then z.
    occ: Vec<u8>,
    /// Build-plane x of the left edge and y of the front edge, mm.
    origin: [f64; 2],
    /// Cell size in x and y, mm.
    cell: [f64; 2],
    /// Bottom and top of each slab, mm.
    slabs: Vec<[f64; 2]>,
}

impl Voxels {
    /// Whether voxel (x, y, z) is lit; outside the grid is empty.
    fn at(&self, x: i64, y: i64, z: i64) -> bool {
        if x < 0 || y < 0 || z < 0 {
            return false;
        }
        let (x, y, z) = (x as usize, y as usize, z as usize);
        x < self.nx && y < self.ny && z < self.nz && self.occ[(z * self.ny + y) * self.nx + x] != 0
    }

    /// The outward normal at lit voxel (x, y, z): away from the lit voxels within
    /// [`NORMAL_RADIUS`] across and [`NORMAL_RADIUS_Z`] up and down (weighted by distance
    /// in mm, so the pixels' stair steps smooth out), or the open faces' directions when
    /// they balance.
    fn normal(&self, x: i64, y: i64, z: i64, dz: f64) -> V3 {
        let r = NORMAL_RADIUS;
        let spread = (self.cell[0].max(self.cell[1]) * r as f64).powi(2);
        let mut g = [0.0; 3];
        let mut open = [0.0; 3];
        for k in -NORMAL_RADIUS_Z..=NORMAL_RADIUS_Z {
            for j in -r..=r {
                for i in -r..=r {
                    if i == 0 && j == 0 && k == 0 {
                        continue;
                    }
                    let d = [
                        i as f64 * self.cell[0],
                        j as f64 * self.cell[1],
                        k as f64 * dz,
                    ];
                    if self.at(x + i, y + j, z + k) {
                        let w = (-dot(d, d) / spread).exp() / dot(d, d).sqrt();
                        g = [g[0] - w * d[0], g[1] - w * d[1], g[2] - w * d[2]];
                    } else if i.abs() + j.abs() + k.abs() == 1 {
                        open = [open[0] + d[0], open[1] + d[1], open[2] + d[2]];
                    }
                }
            }
        }
        if dot(g, g) > 1e-6 {
            normalized(g)
        } else {
            normalized(open)
        }
    }
}

/// Reads the layers into voxels.
fn voxels(manifest: &Manifest, masks: &dyn BundleSource) -> Result<Voxels> {
    let crop = part_crop(manifest);
    let field = manifest.machine.field();
    let p = field.pixel_mm;
    let longer = crop.width().max(crop.height()) as f64;
    let scale = (XY_CELLS as f64 / longer).min(1.0);
    let cells = |px: u32| ((px as f64 * scale).round() as u32).max(1);
    let want = (cells(crop.width()), cells(crop.height()));
    let layers = &manifest.layers;
    let n = layers.len();
    let height = layers.last().map_or(0.0, |l| l.z_mm);
    let cell_mm =
        (crop.width() as f64 * p / want.0 as f64).min(crop.height() as f64 * p / want.1 as f64);
    let per_layer = if n > 0 { height / n as f64 } else { 1.0 };
    let by_size = (cell_mm / per_layer.max(1e-9)).round().max(1.0) as usize;
    let step = by_size.max(n.div_ceil(Z_SLABS)).max(1);
    let nz = n.div_ceil(step);
    let slab_layers: Vec<(usize, usize)> = (0..nz)
        .map(|j| (j * step, ((j + 1) * step).min(n) - 1))
        .collect();
    let planes: Vec<(u32, u32, Vec<u8>)> =
        crate::error::in_order(slab_layers.par_iter().map(|&(a, b)| {
            let c = layer_cells(manifest, (a + b) / 2, masks, crop, want.0, want.1)?;
            let occ = c.lit.iter().map(|&l| u8::from(l >= 0.5)).collect();
            Ok((c.width, c.height, occ))
        }))?;
    let (nx, ny) = planes.first().map_or(want, |p| (p.0, p.1));
    let (nx, ny) = (nx as usize, ny as usize);
    // Cells come row 0 at the top (back of the field); voxels count y from the front.
    let mut occ = vec![0u8; nx * ny * nz];
    for (z, (_, _, plane)) in planes.iter().enumerate() {
        for row in 0..ny {
            let y = ny - 1 - row;
            let dst = (z * ny + y) * nx;
            occ[dst..dst + nx].copy_from_slice(&plane[row * nx..(row + 1) * nx]);
        }
    }
    let slabs = slab_layers
        .iter()
        .map(|&(a, b)| [layers[a].z_mm - layers[a].thickness_mm, layers[b].z_mm])
        .collect();
    Ok(Voxels {
        nx,
        ny,
        nz,
        occ,
        origin: [crop.x0 as f64 * p, field.height_mm() - crop.y1 as f64 * p],
        cell: [
            crop.width() as f64 * p / nx as f64,
            crop.height() as f64 * p / ny as f64,
        ],
        slabs,
    })
}

/// How a preview projects a point of the build volume into its picture.
#[derive(Debug, Clone, Copy)]
pub struct Projection {
    view_right: V3,
    view_up: V3,
    /// The smallest screen coordinates (right, up) of the plate and the part, mm.
    lo: [f64; 2],
    /// Picture pixels per mm.
    scale: f64,
    /// Left and bottom margins, px.
    offset: [f64; 2],
    /// The picture's height, px.
    height: f64,
}

impl Projection {
    /// The picture pixel (x right, y down) of build-volume point `q` (x, y on the build
    /// plane, z above it; mm).
    pub fn pixel_of(&self, q: [f64; 3]) -> (f64, f64) {
        (
            self.offset[0] + (dot(q, self.view_right) - self.lo[0]) * self.scale,
            self.height - self.offset[1] - (dot(q, self.view_up) - self.lo[1]) * self.scale,
        )
    }

    /// Picture pixels per mm.
    pub fn scale(&self) -> f64 {
        self.scale
    }
}

/// A `width` × `height` picture of the part the masks of `manifest` build, read through
/// `masks`: the lit pixels stacked into voxels, seen from the front right and above,
/// shaded, on its build plate. Errors: a mask that cannot be read.
pub fn preview(
    manifest: &Manifest,
    masks: &dyn BundleSource,
    width: u32,
    height: u32,
) -> Result<RgbImage> {
    preview_projected(manifest, masks, width, height).map(|(img, _)| img)
}

/// [`preview()`] and how it projects the build volume, so that marks can be drawn over it.
pub fn preview_projected(
    manifest: &Manifest,
    masks: &dyn BundleSource,
    width: u32,
    height: u32,
) -> Result<(RgbImage, Projection)> {
    let (width, height) = (width.max(16), height.max(16));
    let v = voxels(manifest, masks)?;
    let view = View::new();
    let top = v.slabs.last().map_or(1.0, |s| s[1]).max(1e-3);
    let (x0, y0) = (v.origin[0], v.origin[1]);
    let (x1, y1) = (x0 + v.nx as f64 * v.cell[0], y0 + v.ny as f64 * v.cell[1]);
    // Fit the box of plate and part into the picture with a margin; its depths scale the
    // shading.
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    let mut depths = [f64::INFINITY, f64::NEG_INFINITY];
    for x in [x0, x1] {
        for y in [y0, y1] {
            for z in [0.0, top] {
                let q = [dot([x, y, z], view.right), dot([x, y, z], view.up)];
                lo = [lo[0].min(q[0]), lo[1].min(q[1])];
                hi = [hi[0].max(q[0]), hi[1].max(q[1])];
                let d = dot([x, y, z], view.toward);
                depths = [depths[0].min(d), depths[1].max(d)];
            }
        }
    }
    let margin = 0.06 * width.min(height) as f64;
    let s = ((width as f64 - 2.0 * margin) / (hi[0] - lo[0]).max(1e-9))
        .min((height as f64 - 2.0 * margin) / (hi[1] - lo[1]).max(1e-9));
    let projection = Projection {
        view_right: view.right,
        view_up: view.up,
        lo,
        scale: s,
        offset: [
            (width as f64 - (hi[0] - lo[0]) * s) / 2.0,
            (height as f64 - (hi[1] - lo[1]) * s) / 2.0,
        ],
        height: height as f64,
    };
    let to_px = |q: V3| projection.pixel_of(q);

    let mut canvas = Canvas::new(width, height, BACKGROUND);
    draw_plate(&mut canvas, &to_px, [x0, y0, x1, y1]);
    let mut img = canvas.to_rgb();

    let light = normalized(std::array::from_fn(|k| {
        -0.35 * view.right[k] + 0.55 * view.up[k] + 0.75 * view.toward[k]
    }));
    let mut zbuf = vec![f64::NEG_INFINITY; (width * height) as usize];
    // The pixels a voxel centred on `c` covers, `r` each way (at least one).
    let pixels = |c: f64, r: f64| {
        let a = (c - r).round();
        (a as i64, (c + r).round().max(a + 1.0) as i64)
    };
    let (w, h) = (width as i64, height as i64);
    for z in 0..v.nz {
        let [zb, zt] = v.slabs[z];
        let dz = (zt - zb).max(1e-6);
        let hw = 0.5 * s * (view.right[0].abs() * v.cell[0] + view.right[1].abs() * v.cell[1]);
        let hh = 0.5
            * s
            * (view.up[0].abs() * v.cell[0] + view.up[1].abs() * v.cell[1] + view.up[2].abs() * dz);
        for y in 0..v.ny {
            for x in 0..v.nx {
                let (xi, yi, zi) = (x as i64, y as i64, z as i64);
                if !v.at(xi, yi, zi) {
                    continue;
                }
                // Hidden unless a face turned to the viewer (right, front, top) is open.
                if v.at(xi + 1, yi, zi) && v.at(xi, yi - 1, zi) && v.at(xi, yi, zi + 1) {
                    continue;
                }
                let q = [
                    x0 + (x as f64 + 0.5) * v.cell[0],
                    y0 + (y as f64 + 0.5) * v.cell[1],
                    (zb + zt) / 2.0,
                ];
                let n = v.normal(xi, yi, zi, dz);
                let diffuse = dot(n, light).max(0.0);
                let facing = dot(n, view.toward).max(0.0);
                let depth = dot(q, view.toward);
                let near = (depth - depths[0]) / (depths[1] - depths[0]).max(1e-9);
                let shade = (0.34 + 0.56 * diffuse + 0.10 * facing) * (0.75 + 0.25 * near);
                let color = PART.map(|c| (c as f64 * shade * 1.25).round().clamp(0.0, 255.0) as u8);
                let (px, py) = to_px(q);
                let (ax, bx) = pixels(px, hw);
                let (ay, by) = pixels(py, hh);
                for sy in ay.max(0)..by.min(h) {
                    for sx in ax.max(0)..bx.min(w) {
                        let i = (sy * w + sx) as usize;
                        if depth > zbuf[i] {
                            zbuf[i] = depth;
                            img.put_pixel(sx as u32, sy as u32, image::Rgb(color));
                        }
                    }
                }
            }
        }
    }
    Ok((img, projection))
}

/// The build plate under the part: its outline and lines every 10 mm.
fn draw_plate(c: &mut Canvas, to_px: &dyn Fn(V3) -> (f64, f64), b: [f64; 4]) {
    let [x0, y0, x1, y1] = b;
    let corner = |x: f64, y: f64| {
        let (px, py) = to_px([x, y, 0.0]);
        (px as f32, py as f32)
    };
    let corners = [
        corner(x0, y0),
        corner(x1, y0),
        corner(x1, y1),
        corner(x0, y1),
    ];
    c.polygon(&corners, PLATE, 255);
    let mut x = (x0 / 10.0).ceil() * 10.0;
    while x < x1 {
        c.polyline(&[corner(x, y0), corner(x, y1)], PLATE_LINE, 1.0);
        x += 10.0;
    }
    let mut y = (y0 / 10.0).ceil() * 10.0;
    while y < y1 {
        c.polyline(&[corner(x0, y), corner(x1, y)], PLATE_LINE, 1.0);
        y += 10.0;
    }
    c.polyline(&[&corners[..], &corners[..1]].concat(), PLATE_LINE, 1.5);
}
