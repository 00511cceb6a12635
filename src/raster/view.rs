//! A projector's part of a field mask: the projector's own view, cut out and mirrored.

use super::{Mask, PixelBox};
use crate::profile::Projector;

/// Whether projector `p` shows a `width × height` field as it is: it covers it exactly,
/// unmirrored.
pub fn shows_as_is(p: &Projector, width: u32, height: u32) -> bool {
    let unmirrored = !p.mirror_x && !p.mirror_y;
    p.offset_px == [0, 0] && (p.width_px, p.height_px) == (width, height) && unmirrored
}

/// Cuts projector `p`'s part out of a field mask and applies its mirror flags (borrows the
/// field mask when the projector covers it exactly, unmirrored).
#[cfg(any(test, feature = "internals"))]
pub fn projector_view<'a>(field_mask: &'a Mask, p: &Projector) -> std::borrow::Cow<'a, Mask> {
    let (ox, oy) = (p.offset_px[0] as usize, p.offset_px[1] as usize);
    let (w, h) = (p.width_px as usize, p.height_px as usize);
    if shows_as_is(p, field_mask.width, field_mask.height) {
        return std::borrow::Cow::Borrowed(field_mask);
    }
    let fw = field_mask.width as usize;
    let mut out = Mask::zeros(w as u32, h as u32);
    for r in 0..h {
        let sr = if p.mirror_y { h - 1 - r } else { r };
        let src = &field_mask.data[(oy + sr) * fw + ox..(oy + sr) * fw + ox + w];
        let dst = &mut out.data[r * w..(r + 1) * w];
        dst.copy_from_slice(src);
        if p.mirror_x {
            dst.reverse();
        }
    }
    std::borrow::Cow::Owned(out)
}

/// [`projector_view`] of a field mask that is zero outside `lit`, and the box of the view
/// outside which it is zero: only the rows and columns of `lit` the projector shows are
/// copied (the rest of a view it owns is zeroed memory never written).
pub fn projector_view_in<'a>(
    field_mask: &'a Mask,
    p: &Projector,
    lit: PixelBox,
) -> (std::borrow::Cow<'a, Mask>, PixelBox) {
    if shows_as_is(p, field_mask.width, field_mask.height) {
        return (std::borrow::Cow::Borrowed(field_mask), lit);
    }
    let (ox, oy) = (p.offset_px[0] as usize, p.offset_px[1] as usize);
    let (w, h) = (p.width_px as usize, p.height_px as usize);
    // `lit` in the projector's unmirrored pixels.
    let (r0, r1) = (lit.r0.max(oy) - oy, lit.r1.min(oy + h).saturating_sub(oy));
    let (c0, c1) = (lit.c0.max(ox) - ox, lit.c1.min(ox + w).saturating_sub(ox));
    let mut out = Mask::zeros(w as u32, h as u32);
    if r0 >= r1 || c0 >= c1 {
        return (std::borrow::Cow::Owned(out), PixelBox::EMPTY);
    }
    let fw = field_mask.width as usize;
    let flip = |a: usize, b: usize, n: usize, m: bool| if m { (n - b, n - a) } else { (a, b) };
    let (vr0, vr1) = flip(r0, r1, h, p.mirror_y);
    let (vc0, vc1) = flip(c0, c1, w, p.mirror_x);
    for sr in r0..r1 {
        let r = if p.mirror_y { h - 1 - sr } else { sr };
        let src = &field_mask.data[(oy + sr) * fw + ox..][c0..c1];
        let dst = &mut out.data[r * w..][vc0..vc1];
        dst.copy_from_slice(src);
        if p.mirror_x {
            dst.reverse();
        }
    }
    (
        std::borrow::Cow::Owned(out),
        PixelBox::new(vr0, vr1, vc0, vc1),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::xorshift;

    #[test]
    fn mirror_flags() {
        let mut m = Mask::zeros(4, 2);
        m.data = vec![1, 2, 3, 4, 5, 6, 7, 8];
        let mut p = crate::profile::Profile::default_profile().projector[0].clone();
        p.width_px = 4;
        p.height_px = 2;
        p.mirror_x = true;
        assert_eq!(projector_view(&m, &p).data, vec![4, 3, 2, 1, 8, 7, 6, 5]);
        p.mirror_x = false;
        p.mirror_y = true;
        assert_eq!(projector_view(&m, &p).data, vec![5, 6, 7, 8, 1, 2, 3, 4]);
    }

    #[test]
    fn projector_view_of_the_lit_box_is_the_whole_view() {
        // Every mirroring and an offset projector cutting the field: the view made from
        // the lit box alone equals the whole view, and is zero outside the box it gives.
        let (fw, fh) = (13u32, 9u32);
        let mut m = Mask::zeros(fw, fh);
        let lit = PixelBox::new(2, 7, 3, 11);
        let mut rnd = xorshift(7);
        for r in lit.rows() {
            for c in lit.cols() {
                m.data[r * fw as usize + c] = 1 + (rnd() * 254.0) as u8;
            }
        }
        let mut p = crate::profile::Profile::default_profile().projector[0].clone();
        for (w, h, ox, oy) in [(13, 9, 0, 0), (8, 6, 4, 1), (5, 4, 0, 5), (3, 2, 0, 0)] {
            for (mx, my) in [(false, false), (true, false), (false, true), (true, true)] {
                (p.width_px, p.height_px, p.offset_px) = (w, h, [ox, oy]);
                (p.mirror_x, p.mirror_y) = (mx, my);
                let whole = projector_view(&m, &p);
                let (view, b) = projector_view_in(&m, &p, lit);
                assert_eq!(view.data, whole.data, "{w}x{h}+{ox}+{oy} {mx} {my}");
                for (i, &v) in view.data.iter().enumerate() {
                    let (r, c) = (i / w as usize, i % w as usize);
                    let inside = b.rows().contains(&r) && b.cols().contains(&c);
                    assert!(inside || v == 0, "{w}x{h}+{ox}+{oy} {mx} {my}: {r},{c}");
                }
            }
        }
    }
}
