//! The correction over the field, as numbers and as a heatmap (`dmdsl distortion --plot`).

use super::correction::Correction;
use crate::plot::Heatmap;

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

    /// The heatmap of [`field_map`](Self::field_map) on 1 mm cells, in mm from the field's
    /// bottom-left corner (the cells start at the top-left corner, so the bottom row may
    /// reach below y = 0). Its colour bar runs from 0 to the largest correction, the larger
    /// of the cells' and the table points' (the fit report's `max_correction_mm`), so the
    /// bar covers what the report prints.
    pub fn plot(&self) -> Heatmap {
        let cell_mm = 1.0;
        let (cols, rows, values) = self.field_map(cell_mm);
        let report = &self.report;
        let cells_max = values
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        Heatmap {
            title: format!(
                "{}: lens correction, aim to target; largest {:.3} mm on the map, {:.3} mm at the table's points",
                report.source, cells_max, report.max_correction_mm
            ),
            cols,
            rows,
            values,
            x_range: [0.0, cols as f64 * cell_mm],
            y_range: [self.field_mm[1] - rows as f64 * cell_mm, self.field_mm[1]],
            x_label: "x on the build plane (mm)".into(),
            y_label: "y on the build plane (mm)".into(),
            quantity: "correction (mm)".into(),
            range: Some([0.0, report.max_correction_mm]),
            cell_px: 9.0,
            annotate: false,
            missing: "unreachable: the projector cannot aim there".into(),
        }
    }
}
