//! Where the part goes on the build plane.

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::profile::{Profile, MAX_LAYERS};
use crate::slice;
use crate::text::{fixed, number};
use std::path::Path;

/// Where the part goes on the build plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlacementMode {
    /// XY bounding box centred on the field, lowest point at z = 0.
    Center,
    /// File coordinates are build-plane coordinates.
    Keep,
    /// XY bounding box centred on this build-plane point (x, y mm from the field's
    /// bottom-left corner), lowest point at z = 0.
    At([f64; 2]),
}

impl PlacementMode {
    /// The name recorded in the manifest.
    pub(super) fn as_str(self) -> &'static str {
        match self {
            PlacementMode::Center => "center",
            PlacementMode::Keep => "keep",
            PlacementMode::At(_) => "position",
        }
    }
}

/// How the part is scaled and turned, about the origin of its file's coordinates, before
/// it is placed: a point p becomes Rz·Ry·Rx·(S·p).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// Scale factors along X, Y and Z (each finite and > 0).
    pub scale: [f64; 3],
    /// Rotations about the X, Y and Z axes, degrees, applied in that order (after the
    /// scale).
    pub rotate_deg: [f64; 3],
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    /// No change.
    pub const IDENTITY: Transform = Transform {
        scale: [1.0; 3],
        rotate_deg: [0.0; 3],
    };

    /// True when the transform changes nothing (then the mesh is left untouched).
    pub fn is_identity(&self) -> bool {
        self.scale == [1.0; 3] && self.rotate_deg.iter().all(|&a| a == 0.0)
    }

    /// Checks the numbers: scale factors finite and > 0 (a zero would flatten the part, a
    /// negative one mirror it), angles finite. The error says which.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if let Some(f) = self.scale.iter().find(|f| !(f.is_finite() && **f > 0.0)) {
            return Err(format!("scale factor {f} is not a finite number > 0"));
        }
        if let Some(a) = self.rotate_deg.iter().find(|a| !a.is_finite()) {
            return Err(format!("rotation {a}° is not a finite angle"));
        }
        Ok(())
    }

    /// The 3×3 matrix R·S, rows first. Quarter turns are exact (cos 90° is 0, not
    /// 6e-17), so a box turned by 90° keeps its edges on the pixel grid.
    fn matrix(&self) -> [[f64; 3]; 3] {
        let mut m = [[0.0; 3]; 3];
        for (k, row) in m.iter_mut().enumerate() {
            row[k] = self.scale[k];
        }
        for (axis, &deg) in self.rotate_deg.iter().enumerate() {
            if deg != 0.0 {
                m = mul(&rotation(axis, deg), &m);
            }
        }
        m
    }

    /// Applies the transform to every vertex of `mesh`.
    pub fn apply(&self, mesh: &mut Mesh) {
        if self.is_identity() {
            return;
        }
        let m = self.matrix();
        for v in &mut mesh.vertices {
            let p = *v;
            for (k, row) in m.iter().enumerate() {
                v[k] = row[0] * p[0] + row[1] * p[1] + row[2] * p[2];
            }
        }
    }
}

/// Cosine and sine of `deg` degrees, exact for multiples of 90°.
fn cos_sin(deg: f64) -> (f64, f64) {
    let turns = deg / 90.0;
    if turns == turns.round() && turns.abs() < 1e15 {
        match (turns as i64).rem_euclid(4) {
            0 => (1.0, 0.0),
            1 => (0.0, 1.0),
            2 => (-1.0, 0.0),
            _ => (0.0, -1.0),
        }
    } else {
        let (s, c) = deg.to_radians().sin_cos();
        (c, s)
    }
}

/// The rotation by `deg` degrees about axis `axis` (0 = X, 1 = Y, 2 = Z), right-handed.
fn rotation(axis: usize, deg: f64) -> [[f64; 3]; 3] {
    let (c, s) = cos_sin(deg);
    match axis {
        0 => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
        1 => [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        _ => [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
    }
}

/// The matrix product a·b.
fn mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

/// Computes the translation that places `bbox` on the field, or an error if it cannot fit.
pub fn placement(
    path: &Path,
    bbox: [[f64; 3]; 2],
    field_w: f64,
    field_h: f64,
    mode: PlacementMode,
) -> Result<[f64; 3]> {
    let [lo, hi] = bbox;
    let size = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    if size[0] > field_w || size[1] > field_h {
        return Err(Error::Job {
            path: path.into(),
            msg: format!(
                "part is {} x {} mm but the build field is {field_w:.3} x {field_h:.3} mm",
                fixed(size[0], 3),
                fixed(size[1], 3)
            ),
        });
    }
    let t = match mode {
        PlacementMode::Center => [
            field_w / 2.0 - (lo[0] + hi[0]) / 2.0,
            field_h / 2.0 - (lo[1] + hi[1]) / 2.0,
            -lo[2],
        ],
        PlacementMode::At([x, y]) => {
            let t = [x - (lo[0] + hi[0]) / 2.0, y - (lo[1] + hi[1]) / 2.0, -lo[2]];
            let (x0, x1, y0, y1) = (lo[0] + t[0], hi[0] + t[0], lo[1] + t[1], hi[1] + t[1]);
            let eps = 1e-9;
            if !(x0 >= -eps && y0 >= -eps && x1 <= field_w + eps && y1 <= field_h + eps) {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --position {},{} the part spans {}, outside the build field 0..{field_w:.3} x 0..{field_h:.3} mm",
                        number(x),
                        number(y),
                        spans([x0, y0], [x1, y1])
                    ),
                });
            }
            t
        }
        PlacementMode::Keep => {
            let eps = 1e-9;
            if lo[0] < -eps || lo[1] < -eps || hi[0] > field_w + eps || hi[1] > field_h + eps {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --keep-position the part spans {}, outside the build field 0..{field_w:.3} x 0..{field_h:.3} mm",
                        spans([lo[0], lo[1]], [hi[0], hi[1]])
                    ),
                });
            }
            if lo[2] < -eps {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --keep-position the part reaches below the build plane (z min {} mm)",
                        fixed(lo[2], 3)
                    ),
                });
            }
            [0.0, 0.0, 0.0]
        }
    };
    Ok(t)
}

/// A part's extent on the build plane for a message: `x 7.000..11.000, y 3.000..5.000 mm`
/// (a far-off vertex in scientific notation, not hundreds of digits).
fn spans(lo: [f64; 2], hi: [f64; 2]) -> String {
    let [x0, y0, x1, y1] = [lo[0], lo[1], hi[0], hi[1]].map(|v| fixed(v, 3));
    format!("x {x0}..{x1}, y {y0}..{y1} mm")
}

/// Places a loaded mesh on the profile's field by `mode` (translating it) and returns the
/// translation and the number of layers of height `h`. A part that does not fit the field,
/// is thinner than one layer, is taller than the stage travels, or needs more than
/// `MAX_LAYERS` (10⁶) layers is an error naming `path`, found before anything is sliced.
/// `slice_to_bundle`, the benchmarks and tools that drive the stages themselves share this.
pub fn place_mesh(
    path: &Path,
    mesh: &mut Mesh,
    profile: &Profile,
    mode: PlacementMode,
    h: f64,
) -> Result<([f64; 3], usize)> {
    let field = profile.field();
    let bbox = mesh.bbox();
    let t = placement(path, bbox, field.width_mm(), field.height_mm(), mode)?;
    mesh.translate(t);
    let top = bbox[1][2] + t[2];
    let tall = bbox[1][2] - bbox[0][2];
    let job_error = |msg: String| Error::Job {
        path: path.into(),
        msg,
    };
    // The last layer is exposed at its top, n·h ≤ top: a part whose top lies beyond the
    // stage travel cannot be printed, whatever the process.
    let travel_max = profile.stage.travel_max_mm;
    if top.is_nan() || top > travel_max {
        return Err(job_error(format!(
            "part is {} mm tall, its top at {} mm, but the stage travels only to stage.travel_max_mm = {} mm",
            number(tall),
            number(top),
            number(travel_max)
        )));
    }
    let n = match slice::layer_count(top, h) {
        Some(n) if n <= MAX_LAYERS => n,
        _ => {
            return Err(job_error(format!(
                "a part {} mm tall at {} mm layers needs more than {MAX_LAYERS} layers",
                number(tall),
                number(h)
            )))
        }
    };
    if n == 0 {
        return Err(job_error(format!(
            "part is {} mm tall, less than one layer ({} mm): nothing to print",
            number(tall),
            number(h)
        )));
    }
    Ok((t, n))
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOX: [[f64; 3]; 2] = [[1.0, 2.0, 3.0], [5.0, 4.0, 7.0]];

    #[test]
    fn centre_puts_the_box_mid_field_on_the_plane() {
        let t = placement(Path::new("p.stl"), BOX, 10.0, 8.0, PlacementMode::Center).unwrap();
        assert_eq!(t, [2.0, 1.0, -3.0]);
    }

    #[test]
    fn keep_moves_nothing_and_rejects_parts_off_the_field() {
        let p = Path::new("p.stl");
        assert_eq!(
            placement(p, BOX, 10.0, 8.0, PlacementMode::Keep).unwrap(),
            [0.0; 3]
        );
        let e = placement(p, BOX, 4.5, 8.0, PlacementMode::Keep).unwrap_err();
        assert!(e.to_string().contains("outside the build field"), "{e}");
        let below = [[1.0, 2.0, -0.5], [5.0, 4.0, 7.0]];
        let e = placement(p, below, 10.0, 8.0, PlacementMode::Keep).unwrap_err();
        assert!(e.to_string().contains("below the build plane"), "{e}");
    }

    #[test]
    fn position_centres_the_box_there_or_refuses_a_part_off_the_field() {
        let p = Path::new("p.stl");
        let t = placement(p, BOX, 10.0, 8.0, PlacementMode::At([3.0, 6.5])).unwrap();
        assert_eq!(t, [0.0, 3.5, -3.0]);
        let e = placement(p, BOX, 10.0, 8.0, PlacementMode::At([9.0, 4.0]))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "p.stl: with --position 9,4 the part spans x 7.000..11.000, y 3.000..5.000 mm, outside the build field 0..10.000 x 0..8.000 mm"
        );
        // Far off: a short line, not the hundreds of digits of 1e308.
        let e = placement(p, BOX, 10.0, 8.0, PlacementMode::At([1e308, 0.0]))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "p.stl: with --position 1e308,0 the part spans x 1.0000e308..1.0000e308, y -1.000..1.000 mm, outside the build field 0..10.000 x 0..8.000 mm"
        );
    }

    #[test]
    fn transforms_scale_then_turn_x_y_z_and_quarter_turns_are_exact() {
        let turn = |scale: [f64; 3], rotate_deg: [f64; 3], p: [f64; 3]| {
            let mut mesh =
                crate::mesh::Mesh::from_soup(&crate::mesh::cube_soup(1.0, [0.0; 3]), "stl-binary");
            mesh.vertices = vec![p];
            Transform { scale, rotate_deg }.apply(&mut mesh);
            mesh.vertices[0]
        };
        // 90° about Z: x → y, y → −x, exactly.
        assert_eq!(
            turn([1.0; 3], [0.0, 0.0, 90.0], [2.0, 1.0, 3.0]),
            [-1.0, 2.0, 3.0]
        );
        assert_eq!(
            turn([1.0; 3], [0.0, 0.0, -270.0], [2.0, 1.0, 3.0]),
            [-1.0, 2.0, 3.0]
        );
        // Scale first, then X (y → z), then Z (x → y).
        assert_eq!(
            turn([2.0, 3.0, 1.0], [90.0, 0.0, 90.0], [1.0, 1.0, 0.0]),
            [0.0, 2.0, 3.0]
        );
        let r = turn([1.0; 3], [0.0, 0.0, 45.0], [1.0, 0.0, 0.0]);
        assert!((r[0] - 0.5f64.sqrt()).abs() < 1e-15 && (r[1] - 0.5f64.sqrt()).abs() < 1e-15);
        assert!(Transform::IDENTITY.is_identity());
        for bad in [[0.0, 1.0, 1.0], [f64::NAN, 1.0, 1.0], [1.0, -1.0, 1.0]] {
            let t = Transform {
                scale: bad,
                ..Transform::IDENTITY
            };
            assert!(t
                .validate()
                .unwrap_err()
                .contains("is not a finite number > 0"));
        }
        let t = Transform {
            rotate_deg: [0.0, f64::INFINITY, 0.0],
            ..Transform::IDENTITY
        };
        assert!(t.validate().is_err());
    }

    #[test]
    fn a_part_larger_than_the_field_does_not_fit_either_way() {
        for mode in [
            PlacementMode::Center,
            PlacementMode::Keep,
            PlacementMode::At([5.0, 4.0]),
        ] {
            let e = placement(Path::new("p.stl"), BOX, 3.0, 8.0, mode).unwrap_err();
            assert!(
                e.to_string().starts_with("p.stl: part is 4.000 x 2.000 mm"),
                "{e}"
            );
        }
        // A far-off vertex: a short line, not 31 digits.
        let far = [[0.0; 3], [1e30, 1.0, 1.0]];
        let e = placement(Path::new("p.stl"), far, 3.0, 8.0, PlacementMode::Center).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.stl: part is 1.0000e30 x 1.000 mm but the build field is 3.000 x 8.000 mm"
        );
    }
}
