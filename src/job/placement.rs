//! Where the part goes on the build plane.

use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::profile::Profile;
use crate::slice;
use std::path::Path;

/// Where the part goes on the build plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlacementMode {
    /// XY bounding box centred on the field, lowest point at z = 0.
    Center,
    /// File coordinates are build-plane coordinates.
    Keep,
}

impl PlacementMode {
    /// The name recorded in the manifest.
    pub(super) fn as_str(self) -> &'static str {
        match self {
            PlacementMode::Center => "center",
            PlacementMode::Keep => "keep",
        }
    }
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
                "part is {:.3} x {:.3} mm but the build field is {:.3} x {:.3} mm",
                size[0], size[1], field_w, field_h
            ),
        });
    }
    let t = match mode {
        PlacementMode::Center => [
            field_w / 2.0 - (lo[0] + hi[0]) / 2.0,
            field_h / 2.0 - (lo[1] + hi[1]) / 2.0,
            -lo[2],
        ],
        PlacementMode::Keep => {
            let eps = 1e-9;
            if lo[0] < -eps || lo[1] < -eps || hi[0] > field_w + eps || hi[1] > field_h + eps {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --keep-position the part spans x {:.3}..{:.3}, y {:.3}..{:.3} mm, outside the build field 0..{:.3} x 0..{:.3} mm",
                        lo[0], hi[0], lo[1], hi[1], field_w, field_h
                    ),
                });
            }
            if lo[2] < -eps {
                return Err(Error::Job {
                    path: path.into(),
                    msg: format!(
                        "with --keep-position the part reaches below the build plane (z min {:.3} mm)",
                        lo[2]
                    ),
                });
            }
            [0.0, 0.0, 0.0]
        }
    };
    Ok(t)
}

/// The most layers a job may have. At 1 µm layers that is a part 1 m tall; a larger count
/// comes from a far-off vertex or a mistyped layer height, and would write a mask per layer.
pub const MAX_LAYERS: usize = 1_000_000;

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
            mm(tall),
            mm(top),
            mm(travel_max)
        )));
    }
    let n = match slice::layer_count(top, h) {
        Some(n) if n <= MAX_LAYERS => n,
        _ => {
            return Err(job_error(format!(
                "a part {} mm tall at {} mm layers needs more than {MAX_LAYERS} layers",
                mm(tall),
                mm(h)
            )))
        }
    };
    if n == 0 {
        return Err(job_error(format!(
            "part is {} mm tall, less than one layer ({} mm): nothing to print",
            mm(tall),
            mm(h)
        )));
    }
    Ok((t, n))
}

/// A length for a message: 4 significant decimals, or scientific notation where that
/// would print a long run of digits.
fn mm(v: f64) -> String {
    if v != 0.0 && (v.abs() >= 1e6 || v.abs() < 1e-3) {
        format!("{v:.3e}")
    } else {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s == "-0" {
            "0".into()
        } else {
            s.into()
        }
    }
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
    fn a_part_larger_than_the_field_does_not_fit_either_way() {
        for mode in [PlacementMode::Center, PlacementMode::Keep] {
            let e = placement(Path::new("p.stl"), BOX, 3.0, 8.0, mode).unwrap_err();
            assert!(
                e.to_string().starts_with("p.stl: part is 4.000 x 2.000 mm"),
                "{e}"
            );
        }
    }
}
