//! The lit (nonzero) pixels of a decoded mask: counted and boxed a row at a time, with
//! the row scans vectorized.

use crate::bundle::machine::Projector;

/// The nonzero pixels of an 8-bit gray image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LitPixels {
    /// Number of nonzero pixels.
    pub count: u64,
    /// Their bounding box `[c0, r0, c1, r1]` in the image's pixel coordinates (column,
    /// row from the top-left; the ends exclusive), `None` when no pixel is lit.
    pub bbox: Option<[u32; 4]>,
}

impl LitPixels {
    /// The nonzero pixels of a row-major image `width` pixels wide.
    pub fn of_gray8(width: u32, data: &[u8]) -> LitPixels {
        let mut lit = LitPixels::default();
        if width == 0 {
            return lit;
        }
        // Masks are mostly dark: a dark row costs one vectorized OR over it, a lit one a
        // search from either end and a count over its lit span.
        for (r, row) in data.chunks(width as usize).enumerate() {
            if !any_nonzero(row) {
                continue;
            }
            let first = first_nonzero(row).unwrap_or(0);
            let last = last_nonzero(row).unwrap_or(first);
            // Whole words from the one holding `first`: the bytes before it are zero.
            lit.count += count_nonzero(&row[first / 8 * 8..=last]);
            let (r, c0, c1) = (r as u32, first as u32, last as u32 + 1);
            lit.bbox = Some(match lit.bbox {
                None => [c0, r, c1, r + 1],
                Some([a0, b0, a1, _]) => [a0.min(c0), b0, a1.max(c1), r + 1],
            });
        }
        lit
    }

    /// Both sets of pixels (counts added: pixels lit in both count twice).
    pub fn union(self, other: LitPixels) -> LitPixels {
        LitPixels {
            count: self.count + other.count,
            bbox: match (self.bbox, other.bbox) {
                (Some(a), Some(b)) => Some([
                    a[0].min(b[0]),
                    a[1].min(b[1]),
                    a[2].max(b[2]),
                    a[3].max(b[3]),
                ]),
                (a, b) => a.or(b),
            },
        }
    }

    /// The pixels of projector `p`'s mask as field pixels: mirrored, then offset.
    pub fn in_field(self, p: &Projector) -> LitPixels {
        LitPixels {
            count: self.count,
            bbox: self.bbox.map(|[c0, r0, c1, r1]| {
                let (w, h) = (p.width_px, p.height_px);
                let (c0, c1) = if p.mirror_x {
                    (w.saturating_sub(c1), w.saturating_sub(c0))
                } else {
                    (c0, c1)
                };
                let (r0, r1) = if p.mirror_y {
                    (h.saturating_sub(r1), h.saturating_sub(r0))
                } else {
                    (r0, r1)
                };
                let [ox, oy] = p.offset_px;
                [c0 + ox, r0 + oy, c1 + ox, r1 + oy]
            }),
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
    use super::super::test_support::small_profile;
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
    fn lit_pixels_and_their_place_in_the_field() {
        let data: Vec<u8> = (0..6 * 4)
            .map(|i| [0, 0, 7, 0, 9, 0][i % 6] * (i / 6 % 2) as u8)
            .collect();
        // Rows 1 and 3 light columns 2 and 4.
        let lit = LitPixels::of_gray8(6, &data);
        let px = |count, bbox| LitPixels {
            count,
            bbox: Some(bbox),
        };
        assert_eq!(lit, px(4, [2, 1, 5, 4]));
        assert_eq!(LitPixels::of_gray8(6, &[0; 24]), LitPixels::default());
        let mut p = crate::bundle::Machine::of(&small_profile())
            .projector
            .remove(0);
        p.width_px = 6;
        p.height_px = 4;
        p.offset_px = [100, 10];
        assert_eq!(lit.in_field(&p).bbox, Some([102, 11, 105, 14]));
        p.mirror_x = true;
        // Columns 2..5 of 6 mirrored are 1..4.
        assert_eq!(lit.in_field(&p).bbox, Some([101, 11, 104, 14]));
        p.mirror_y = true;
        // Rows 1..4 of 4 mirrored are 0..3.
        assert_eq!(lit.in_field(&p).bbox, Some([101, 10, 104, 13]));
        assert_eq!(lit.union(px(1, [0, 3, 1, 9])), px(5, [0, 1, 5, 9]));
        assert_eq!(LitPixels::default().union(lit), lit);
    }
}
