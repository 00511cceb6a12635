//! The gray map: the full-coverage gray of every pixel (what a plate covering the field
//! gets, without error diffusion). The apply path reads it for fully covered pixels, and
//! the job writes it as a PNG beside the masks.

use super::zone_mode::ZoneTables;
use super::zones::ZoneGrid;
use super::Compensator;
#[cfg(any(test, feature = "internals"))]
use super::Mask;

/// The full-coverage gray of every pixel as distinct rows (`w` bytes each) and the index
/// of each image row's (zone mode: about 15 distinct rows per zone row; pixel mode: every
/// row its own).
#[derive(Debug)]
pub(super) struct GrayMap {
    pub(super) rows: Vec<u8>,
    pub(super) row_of: Vec<u32>,
}

impl GrayMap {
    /// Pixel mode's map: `full` holds every pixel's gray, row-major, `h` rows.
    pub(super) fn per_pixel(full: Vec<u8>, h: usize) -> GrayMap {
        GrayMap {
            rows: full,
            row_of: (0..h as u32).collect(),
        }
    }

    /// Zone mode's map: entry 255 of each pixel's table.
    ///
    /// Rows with the same tables have the same grays. Tables belong to one zone, so only
    /// rows of the same zone row can be the same, and there rows with the same r mod 64
    /// are ([`upper_row`](super::zone_mode::upper_row)): a row new in its phase is looked
    /// for among the distinct rows of its zone row; distinct rows are numbered in order of
    /// appearance.
    pub(super) fn of_zone_tables(zone_tables: &ZoneTables, zones: &ZoneGrid) -> GrayMap {
        let (tables, row_tables) = (&zone_tables.tables, &zone_tables.of_row);
        let (zone_of_row, zcols, h) = (&zones.of_row, zones.cols, zones.of_row.len());
        let mut gray_rows = Vec::new();
        let mut gray_row_of: Vec<u32> = Vec::with_capacity(h);
        // Distinct rows so far (index, first image row) of the current zone row,
        // and the index of each phase seen there.
        let mut in_zone_row: Vec<(u32, usize)> = Vec::new();
        let mut by_phase = [u32::MAX; 64];
        let mut next = 0u32;
        for r in 0..h {
            if r > 0 && zone_of_row[r] != zone_of_row[r - 1] {
                in_zone_row.clear();
                by_phase = [u32::MAX; 64];
            }
            if by_phase[r & 63] != u32::MAX {
                gray_row_of.push(by_phase[r & 63]);
                continue;
            }
            let tabs = &row_tables[r * zcols..(r + 1) * zcols];
            let found = in_zone_row
                .iter()
                .find(|&&(_, r0)| &row_tables[r0 * zcols..(r0 + 1) * zcols] == tabs);
            let k = match found {
                Some(&(k, _)) => k,
                None => {
                    for &(zc, a, b) in &zones.segments {
                        gray_rows.resize(gray_rows.len() + b - a, tables[tabs[zc] as usize][255]);
                    }
                    in_zone_row.push((next, r));
                    next += 1;
                    next - 1
                }
            };
            by_phase[r & 63] = k;
            gray_row_of.push(k);
        }
        GrayMap {
            rows: gray_rows,
            row_of: gray_row_of,
        }
    }
}

impl Compensator {
    /// Row `r` of the gray map (the full-coverage gray of each pixel).
    #[inline(always)]
    pub(super) fn gray_row(&self, r: usize) -> &[u8] {
        let k = self.gray_map.row_of[r] as usize * self.w;
        &self.gray_map.rows[k..k + self.w]
    }

    /// The full-coverage gray of every pixel (what a plate covering the field gets, without
    /// error diffusion), in field orientation.
    #[cfg(any(test, feature = "internals"))]
    pub fn gray_map(&self) -> Mask {
        let mut data = Vec::with_capacity(self.w * self.h);
        for r in 0..self.h {
            data.extend_from_slice(self.gray_row(r));
        }
        Mask {
            width: self.w as u32,
            height: self.h as u32,
            data,
        }
    }

    /// The gray map as projector `p` shows it ([`crate::raster::projector_view`]),
    /// encoded as `png::encode_gray8` encodes it (the bundle's mask encoder), row by row
    /// with `png::encode_gray8_rows` (the same bytes) without making the map: when `p`
    /// does not show the field as it is, its distinct rows are cut and mirrored once.
    pub fn gray_map_png(&self, p: &crate::profile::Projector) -> Vec<u8> {
        let (w, h) = (self.w as u32, self.h as u32);
        if crate::raster::shows_as_is(p, w, h) {
            return crate::png::encode_gray8_rows(w, h, |r| self.gray_row(r));
        }
        let (ox, oy) = (p.offset_px[0] as usize, p.offset_px[1] as usize);
        let (pw, ph) = (p.width_px as usize, p.height_px as usize);
        let distinct = self.gray_map.rows.len() / self.w.max(1);
        let mut rows = Vec::with_capacity(distinct * pw);
        for k in 0..distinct {
            let row = &self.gray_map.rows[k * self.w + ox..][..pw];
            let at = rows.len();
            rows.extend_from_slice(row);
            if p.mirror_x {
                rows[at..].reverse();
            }
        }
        let row_of = &self.gray_map.row_of;
        crate::png::encode_gray8_rows(p.width_px, p.height_px, |r| {
            let sr = if p.mirror_y { ph - 1 - r } else { r };
            &rows[row_of[oy + sr] as usize * pw..][..pw]
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{small_setup, MODES};
    use super::super::Mode;
    use super::*;

    #[test]
    fn gray_map_rows_and_png_equal_the_per_zone_grays() {
        // The gray map kept as distinct rows is, pixel for pixel, the full-coverage gray
        // of the pixel's zone table for its row (zone mode) and the per-pixel gray (pixel
        // mode: checked against `apply` on a plate); its PNG, encoded row by row, is
        // `encode_gray8` of the map, also as mirrored projectors see it.
        let (cal, field) = small_setup();
        let (w, h) = (200usize, 150usize);
        for (mode, dither) in MODES.into_iter().take(4) {
            let c = Compensator::new(&cal, &field, mode, dither).unwrap();
            let map = c.gray_map();
            if mode == Mode::Zone {
                assert!(
                    c.gray_map.rows.len() / w < h / 2,
                    "{}",
                    c.gray_map.rows.len() / w
                );
                for r in 0..h {
                    for col in 0..w {
                        let t =
                            c.zone_tables.of_row[r * c.zones.cols + c.zones.of_col[col] as usize];
                        assert_eq!(map.data[r * w + col], c.zone_tables.tables[t as usize][255]);
                    }
                }
            }
            let mut plate = Mask::zeros(w as u32, h as u32);
            plate.data.fill(255);
            c.apply(&mut plate);
            assert!(plate == map, "{mode:?} {dither:?}");
            let mut p = crate::profile::Profile::default_profile().projector[0].clone();
            (p.width_px, p.height_px) = (w as u32, h as u32);
            let png = |m: &Mask| crate::png::encode_gray8(m.width, m.height, &m.data);
            assert_eq!(c.gray_map_png(&p), png(&map));
            for (pw, ph, ox, oy) in [(200, 150, 0, 0), (120, 90, 70, 33)] {
                for (mx, my) in [(true, false), (false, true), (true, true), (false, false)] {
                    (p.width_px, p.height_px, p.offset_px) = (pw, ph, [ox, oy]);
                    (p.mirror_x, p.mirror_y) = (mx, my);
                    let view = crate::raster::projector_view(&map, &p);
                    assert_eq!(
                        c.gray_map_png(&p),
                        png(&view),
                        "{pw}x{ph}+{ox}+{oy} {mx} {my}"
                    );
                }
            }
        }
    }
}
