//! The correction over the field, as numbers and as a heatmap (`dmdsl distortion --plot`).

use super::correction::Correction;
use crate::plot::{heatmap_png, Heatmap};

impl Correction {
    /// The correction magnitude |aim − target| (mm) over the field on cells of `cell_mm`,
    /// row-major with row 0 at the top (as the masks); NaN where the target cannot be reached.
    /// Returns (cols, rows, values).
    pub fn field_map(&self, cell_mm: f64) -> (usize, usize, Vec<f64>) {
        let cols = (self.field_mm[0] / cell_mm).ceil() as usize;
        let rows = (self.field_mm[1] / cell_mm).ceil() as usize;
        let mut w = self.warper();
        let mut v = Vec::with_capacity(cols * rows);
        for r in 0..rows {
            for c in 0..cols {
                let t = [
                    ((c as f64 + 0.5) * cell_mm).min(self.field_mm[0]),
                    (self.field_mm[1] - (r as f64 + 0.5) * cell_mm).max(0.0),
                ];
                let a = w.aim(t);
                v.push(if w.reach(t, a).is_ok() {
                    (a[0] - t[0]).hypot(a[1] - t[1])
                } else {
                    f64::NAN
                });
            }
        }
        (cols, rows, v)
    }

    /// Heatmap PNG of [`field_map`](Self::field_map) on 1 mm cells.
    pub fn plot_png(&self) -> Vec<u8> {
        let (cols, rows, values) = self.field_map(1.0);
        let vmax = values
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0, |a: f64, &b| a.max(b));
        heatmap_png(&Heatmap {
            title: format!(
                "{}: correction distance aim to target, mm (gray: unreachable)",
                self.report.source
            ),
            unit: "mm".into(),
            cols,
            rows,
            values,
            vmin: 0.0,
            vmax,
            cell_px: 8,
            annotate: false,
        })
    }
}
