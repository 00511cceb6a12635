//! What a mask shows, as its record in the manifest ([`MaskPixels`], `masks[].pixels` from
//! version 4): the count of its lit (nonzero) pixels, their box in the field and the sum
//! of its pixel values. The slicer counts them from the runs its PNG encoder codes
//! ([`MaskPixels::of_encoded`]); the executor recounts them from the decoded file, so a
//! mask edited and re-hashed still disagrees with its record. The executor's row scans
//! are vectorized: a dark row costs one OR over it.

use serde::{Deserialize, Serialize};
use std::ops::Range;

/// The lit pixels of one mask and the sum of its values (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct MaskPixels {
    /// Number of nonzero pixels.
    pub lit_px: u64,
    /// Their bounding box `[c0, r0, c1, r1]` (column, row from the top-left; the ends
    /// exclusive): in the mask's own pixels as counted, in the field's pixel grid as
    /// recorded ([`MaskPixels::placed`] by its projector); `null` when no pixel is lit.
    pub lit_box_px: Option<[u32; 4]>,
    /// Sum of the pixel values.
    pub gray_sum: u64,
    /// The Adler-32 of the mask's rows as PNG scanlines of filter type 0 (each row after a
    /// 0 byte; what a zlib stream of them ends with): any change of a pixel changes it but
    /// by chance.
    pub adler32: u32,
}

impl MaskPixels {
    /// The pixels of a row-major 8-bit image `width` pixels wide.
    pub fn of_gray8(width: u32, data: &[u8]) -> MaskPixels {
        let rows = data.len() / (width as usize).max(1);
        MaskPixels {
            adler32: crate::png::scanlines_adler32(width, data),
            ..MaskPixels::of_gray8_in(width, data, 0..rows, 0..width as usize)
        }
    }

    /// The pixels of a mask as the PNG encoder coded it: the `lit` pixels it counted and
    /// the Adler-32 its `png` ends with (the same record as [`MaskPixels::of_gray8`] of
    /// the mask).
    pub(crate) fn of_encoded(png: &[u8], lit: crate::png::Lit) -> MaskPixels {
        MaskPixels {
            lit_px: lit.count,
            lit_box_px: lit.lit_box,
            gray_sum: lit.sum,
            adler32: crate::png::scanlines_adler32_of(png),
        }
    }

    /// [`MaskPixels::of_gray8`] but for [`MaskPixels::adler32`] (0: the caller's to set)
    /// of an image known to be zero outside `rows` × `cols`: only that box is visited.
    fn of_gray8_in(width: u32, data: &[u8], rows: Range<usize>, cols: Range<usize>) -> MaskPixels {
        let mut px = MaskPixels::default();
        let w = width as usize;
        if w == 0 || cols.is_empty() {
            return px;
        }
        for r in rows {
            let row = &data[r * w..][cols.clone()];
            if !any_nonzero(row) {
                continue;
            }
            let first = first_nonzero(row).unwrap_or(0);
            let last = last_nonzero(row).unwrap_or(first);
            // Whole words from the one holding `first`: the bytes before it are zero.
            let lit = &row[first / 8 * 8..=last];
            px.lit_px += count_nonzero(lit);
            px.gray_sum += lit.iter().map(|&v| v as u32).sum::<u32>() as u64;
            let (r, c0, c1) = (
                r as u32,
                (cols.start + first) as u32,
                (cols.start + last) as u32,
            );
            px.lit_box_px = Some(match px.lit_box_px {
                None => [c0, r, c1 + 1, r + 1],
                Some([a0, b0, a1, _]) => [a0.min(c0), b0, a1.max(c1 + 1), r + 1],
            });
        }
        px
    }

    /// The pixels of a projector's mask (`[width, height]` px, `offset_px`, `[mirror_x,
    /// mirror_y]`: a projector record's keys) with their box in the field: mirrored,
    /// then offset.
    pub fn placed(self, [w, h]: [u32; 2], [ox, oy]: [u32; 2], [mx, my]: [bool; 2]) -> MaskPixels {
        let flip = |a: u32, b: u32, n: u32, m: bool| match m {
            true => (n.saturating_sub(b), n.saturating_sub(a)),
            false => (a, b),
        };
        MaskPixels {
            lit_box_px: self.lit_box_px.map(|[c0, r0, c1, r1]| {
                let ((c0, c1), (r0, r1)) = (flip(c0, c1, w, mx), flip(r0, r1, h, my));
                [c0 + ox, r0 + oy, c1 + ox, r1 + oy]
            }),
            ..self
        }
    }
}

/// Whether any byte of `bytes` is nonzero (an OR over all of them, which vectorizes).
fn any_nonzero(bytes: &[u8]) -> bool {
    bytes.iter().fold(0u8, |a, &v| a | v) != 0
}

/// Index of the first nonzero byte of `row`: the first 32-byte block with one, then eight
/// bytes at a time.
fn first_nonzero(row: &[u8]) -> Option<usize> {
    let blocks = row.chunks_exact(32);
    let start = blocks
        .clone()
        .position(any_nonzero)
        .map_or(row.len() - blocks.remainder().len(), |k| k * 32);
    let rest = &row[start..];
    let words = rest.chunks_exact(8);
    let tail = words.remainder();
    for (k, w) in words.enumerate() {
        let w = u64::from_le_bytes(w.try_into().expect("8 bytes"));
        if w != 0 {
            return Some(start + k * 8 + w.trailing_zeros() as usize / 8);
        }
    }
    let at = row.len() - tail.len();
    tail.iter().position(|&v| v != 0).map(|i| at + i)
}

/// Index of the last nonzero byte of `row`: the last 32-byte block with one (counted from
/// the end), then eight bytes at a time.
fn last_nonzero(row: &[u8]) -> Option<usize> {
    let blocks = row.rchunks_exact(32);
    let end = blocks
        .clone()
        .position(any_nonzero)
        .map_or(blocks.remainder().len(), |k| row.len() - k * 32);
    let rest = &row[..end];
    let words = rest.rchunks_exact(8);
    let head = words.remainder();
    for (k, w) in words.enumerate() {
        let w = u64::from_le_bytes(w.try_into().expect("8 bytes"));
        if w != 0 {
            return Some(end - k * 8 - 1 - w.leading_zeros() as usize / 8);
        }
    }
    head.iter().rposition(|&v| v != 0)
}

/// Number of nonzero bytes in `bytes`, eight at a time: each word's nonzero bytes become
/// 1 in their byte (no carry crosses a byte), summed bytewise over up to 255 words, then
/// across the word.
fn count_nonzero(bytes: &[u8]) -> u64 {
    const LOW7: u64 = 0x7f7f_7f7f_7f7f_7f7f;
    const PAIRS: u64 = 0x00ff_00ff_00ff_00ff;
    let mut total = 0;
    for block in bytes.chunks(8 * 255) {
        let words = block.chunks_exact(8);
        let tail = words.remainder();
        let mut acc = 0u64;
        for w in words {
            let w = u64::from_le_bytes(w.try_into().expect("8 bytes"));
            acc += ((((w & LOW7) + LOW7) | w) & !LOW7) >> 7;
        }
        let pairs = (acc & PAIRS) + ((acc >> 8) & PAIRS);
        total += pairs.wrapping_mul(0x0001_0001_0001_0001) >> 48;
        total += tail.iter().filter(|&&v| v != 0).count() as u64;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_and_last_nonzero_byte_and_their_count() {
        for n in [0, 1, 7, 8, 9, 16, 17, 31, 32, 33, 40, 64, 65, 100] {
            for a in 0..n {
                for b in a..n {
                    let mut row = vec![0u8; n];
                    row[a] = 3;
                    row[b] = 1;
                    assert_eq!(first_nonzero(&row), Some(a), "{n} {a} {b}");
                    assert_eq!(last_nonzero(&row), Some(b), "{n} {a} {b}");
                    assert!(any_nonzero(&row));
                    assert_eq!(count_nonzero(&row), 1 + (a != b) as u64);
                }
            }
            assert_eq!(first_nonzero(&vec![0; n]), None);
            assert_eq!(last_nonzero(&vec![0; n]), None);
            assert!(!any_nonzero(&vec![0; n]));
        }
        // Counts past a byte's and a block's capacity.
        let row: Vec<u8> = (0..5000u32).map(|i| (i % 7) as u8 * 40).collect();
        let naive = row.iter().filter(|&&v| v != 0).count() as u64;
        assert_eq!(count_nonzero(&row), naive);
        assert_eq!(count_nonzero(&[255; 4096]), 4096);
        assert_eq!(count_nonzero(&[1; 4097]), 4097);
    }

    #[test]
    fn pixels_of_an_image_its_box_and_their_place_in_the_field() {
        let data: Vec<u8> = (0..6 * 4)
            .map(|i| [0, 0, 7, 0, 9, 0][i % 6] * (i / 6 % 2) as u8)
            .collect();
        // Rows 1 and 3 light columns 2 and 4.
        let px = MaskPixels::of_gray8(6, &data);
        let adler32 = crate::png::scanlines_adler32(6, &data);
        let want = |lit_px, b, gray_sum| MaskPixels {
            lit_px,
            lit_box_px: Some(b),
            gray_sum,
            adler32,
        };
        assert_eq!(px, want(4, [2, 1, 5, 4], 32));
        let boxed = MaskPixels::of_gray8_in(6, &data, 1..4, 2..5);
        assert_eq!(MaskPixels { adler32, ..boxed }, px);
        // The record the slicer takes from the encoder is the same.
        let (png, lit) = crate::png::encode_gray8_in(6, 4, &data, crate::png::PixelBox::ALL);
        assert_eq!(MaskPixels::of_encoded(&png, lit), px);
        let dark = MaskPixels::of_gray8(6, &[0; 24]);
        assert_eq!((dark.lit_px, dark.lit_box_px, dark.gray_sum), (0, None, 0));
        let placed = |mirror| px.placed([6, 4], [100, 10], mirror);
        assert_eq!(placed([false; 2]).lit_box_px, Some([102, 11, 105, 14]));
        // Columns 2..5 of 6 mirrored are 1..4.
        assert_eq!(placed([true, false]).lit_box_px, Some([101, 11, 104, 14]));
        // Rows 1..4 of 4 mirrored are 0..3.
        assert_eq!(placed([true; 2]), want(4, [101, 10, 104, 13], 32));
        // The record's JSON.
        let json = serde_json::to_string(&px).unwrap();
        assert_eq!(
            json,
            format!(r#"{{"lit_px":4,"lit_box_px":[2,1,5,4],"gray_sum":32,"adler32":{adler32}}}"#)
        );
    }
}
