//! Where a job with supports is drawn as without the cure correction: windows of layers
//! around the regions their correction left on nothing, and whole layers where a window
//! is not enough ([`super::unheld`]; docs/CURE.md, "Layers drawn uncorrected").

use crate::cure::loose::Drawn;
use crate::raster::{Mask, PixelBox};
use std::collections::BTreeMap;

/// Pixels a window reaches beyond the box of the region it is drawn for: several times the
/// correction's largest inward move and the cure's blur, so that what cures under the
/// region is what cures uncorrected.
pub const MARGIN_PX: usize = 8;

/// The layers drawn as without the cure correction, XY and Z: each in windows on the
/// field (pixel boxes of the field mask) or whole.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Uncorrected {
    /// Per layer: its windows, `None` for the whole layer.
    layers: BTreeMap<usize, Option<Vec<PixelBox>>>,
}

impl Uncorrected {
    /// The layers drawn uncorrected in windows or whole, in order.
    pub fn layers(&self) -> Vec<usize> {
        self.layers.keys().copied().collect()
    }

    /// The layers drawn uncorrected whole, in order.
    pub fn whole_layers(&self) -> Vec<usize> {
        (self.layers.iter())
            .filter_map(|(&i, w)| w.is_none().then_some(i))
            .collect()
    }

    /// Whether layer `i` is drawn uncorrected whole.
    pub fn whole(&self, i: usize) -> bool {
        matches!(self.layers.get(&i), Some(None))
    }

    /// Layer `i`'s windows (none when it is drawn whole, corrected or not).
    pub fn windows(&self, i: usize) -> &[PixelBox] {
        match self.layers.get(&i) {
            Some(Some(w)) => w,
            _ => &[],
        }
    }

    /// Whether layer `i` is drawn uncorrected, in windows or whole.
    pub fn has(&self, i: usize) -> bool {
        self.layers.contains_key(&i)
    }

    /// Whether layer `i` is drawn here as in `other`: in the same windows, whole in both,
    /// or corrected in both.
    pub fn same_at(&self, other: &Uncorrected, i: usize) -> bool {
        self.layers.get(&i) == other.layers.get(&i)
    }

    /// Every window, by layer.
    pub fn all_windows(&self) -> impl Iterator<Item = (usize, PixelBox)> + '_ {
        (self.layers.iter())
            .filter_map(|(&i, w)| Some(w.as_ref()?.iter().map(move |&b| (i, b))))
            .flatten()
    }

    /// Draws more uncorrected so that a region of layer `layer` in field box `at` (a
    /// window around the region: [`window_around`]) may rest on the layer below, one step
    /// beyond what `tried` (the pass that left the region) drew: the window in the layer
    /// below, then in the layer itself, then the layer below whole, then the layer itself
    /// whole. A layer with a window that overlaps `at` has had its step (a region's box
    /// moves a little as the layers around it are drawn again); the window is added to it
    /// all the same. With the Z correction (`held_back` > 0) the `held_back` layers below
    /// the layer below go with it, and whole from the first step: a window drawn without
    /// it lights the downward-facing surfaces the layers around it hold back, which then
    /// rest on nothing at its edges.
    pub fn hold(&mut self, tried: &Uncorrected, layer: usize, at: PixelBox, held_back: usize) {
        let below = layer.saturating_sub(1 + held_back)..layer;
        let windowed = held_back == 0;
        if windowed {
            below.clone().for_each(|i| self.add(i, at));
        }
        if windowed && !below.clone().all(|i| tried.touches(i, at)) {
            return;
        }
        if windowed && !tried.touches(layer, at) {
            return self.add(layer, at);
        }
        match below.clone().all(|i| tried.whole(i)) {
            false => below.for_each(|i| self.set_whole(i)),
            true => self.set_whole(layer),
        }
    }

    /// Draws layers `layers` uncorrected whole.
    #[cfg(test)]
    pub fn with_whole(mut self, layers: impl IntoIterator<Item = usize>) -> Uncorrected {
        layers.into_iter().for_each(|i| self.set_whole(i));
        self
    }

    fn set_whole(&mut self, i: usize) {
        self.layers.insert(i, None);
    }

    /// Whether layer `i` is drawn whole, or in a window that overlaps `at`.
    fn touches(&self, i: usize, at: PixelBox) -> bool {
        match self.layers.get(&i) {
            Some(None) => true,
            Some(Some(w)) => w.iter().any(|b| overlaps(b, &at)),
            None => false,
        }
    }

    fn add(&mut self, i: usize, at: PixelBox) {
        if let Some(w) = self.layers.entry(i).or_insert_with(|| Some(Vec::new())) {
            if !w.iter().any(|b| contains(b, &at)) {
                w.push(at);
            }
        }
    }
}

/// Whether `a` and `b` share a pixel.
fn overlaps(a: &PixelBox, b: &PixelBox) -> bool {
    a.r0 < b.r1 && b.r0 < a.r1 && a.c0 < b.c1 && b.c0 < a.c1
}

/// Whether one of `windows` holds every pixel of `b`.
pub fn covered(windows: &[PixelBox], b: PixelBox) -> bool {
    windows.iter().any(|w| contains(w, &b))
}

/// Whether `outer` holds every pixel of `inner`.
fn contains(outer: &PixelBox, inner: &PixelBox) -> bool {
    outer.r0 <= inner.r0 && outer.c0 <= inner.c0 && inner.r1 <= outer.r1 && inner.c1 <= outer.c1
}

/// The window drawn uncorrected for a region whose pixels' box on a `field` (width,
/// height) is `box_px` (first column, first row, end column, end row): the box and
/// [`MARGIN_PX`] around it, on the field.
pub fn window_around(box_px: [u32; 4], field: [usize; 2]) -> PixelBox {
    let [c0, r0, c1, r1] = box_px.map(|v| v as usize);
    PixelBox::new(
        r0.saturating_sub(MARGIN_PX),
        (r1 + MARGIN_PX).min(field[1]),
        c0.saturating_sub(MARGIN_PX),
        (c1 + MARGIN_PX).min(field[0]),
    )
}

/// A layer's coverage in its windows as drawn before the correction, to be put back
/// once the correction has moved its edges.
pub struct Saved {
    windows: Vec<(PixelBox, Vec<u8>)>,
}

impl Saved {
    /// The coverage of `m` in `windows` (clipped to it).
    pub fn take(m: &Mask, windows: &[PixelBox]) -> Saved {
        let (w, h) = (m.width as usize, m.height as usize);
        let windows = (windows.iter())
            .map(|b| {
                let b = PixelBox::new(b.r0.min(h), b.r1.min(h), b.c0.min(w), b.c1.min(w));
                let data = (b.rows())
                    .flat_map(|r| &m.data[r * w..][b.cols()])
                    .copied()
                    .collect();
                (b, data)
            })
            .collect();
        Saved { windows }
    }

    /// Puts the saved coverage back into `m`, and redraws `drawn`, the layer as drawn for
    /// the next layer's loose pieces, from it.
    pub fn put_back(&self, m: &mut Mask, drawn: Option<Drawn>) -> Option<Drawn> {
        let w = m.width as usize;
        for (b, data) in self.windows.iter().filter(|(b, _)| !b.cols().is_empty()) {
            for (r, row) in b.rows().zip(data.chunks_exact(b.cols().len())) {
                m.data[r * w..][b.cols()].copy_from_slice(row);
            }
        }
        drawn.map(|d| d.redrawn(m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_region_is_held_by_windows_first_then_by_whole_layers() {
        let at = window_around([100, 50, 110, 60], [1024, 768]);
        assert_eq!(at, PixelBox::new(42, 68, 92, 118));
        assert_eq!(
            window_around([0, 0, 3, 768], [4, 768]),
            PixelBox::new(0, 768, 0, 4)
        );
        // One pass: what it holds against what the pass before drew.
        let pass = |u: &Uncorrected, regions: &[(usize, PixelBox)], held: usize| {
            let mut next = u.clone();
            regions.iter().for_each(|&(l, b)| next.hold(u, l, b, held));
            next
        };
        // The layer below, then the layer itself, then both whole, below first.
        let u = pass(&Uncorrected::default(), &[(10, at)], 0);
        assert_eq!((u.layers(), u.windows(9)), (vec![9], &[at][..]));
        let u = pass(&u, &[(10, at)], 0);
        assert_eq!(u.layers(), [9, 10]);
        assert!(u.whole_layers().is_empty());
        let u = pass(&u, &[(10, at)], 0);
        assert_eq!(u.whole_layers(), [9]);
        assert!(u.windows(9).is_empty() && u.whole(9) && !u.whole(10));
        let u = pass(&u, &[(10, at)], 0);
        assert_eq!(u.whole_layers(), [9, 10]);
        assert_eq!(pass(&u, &[(10, at)], 0), u);
        // Two regions of one layer in one pass: each a step beyond the pass before, the
        // second not taken for a region the first's window already tried.
        let moved = window_around([104, 52, 116, 63], [1024, 768]);
        let u = pass(&Uncorrected::default(), &[(10, at), (10, moved)], 0);
        assert_eq!((u.layers(), u.windows(9)), (vec![9], &[at, moved][..]));
        // A region that moved a little has had its window below: its own layer is next,
        // and the layer below gets its window too.
        let u = pass(
            &pass(&Uncorrected::default(), &[(10, at)], 0),
            &[(10, moved)],
            0,
        );
        assert_eq!(
            (u.windows(9), u.windows(10)),
            (&[at, moved][..], &[moved][..])
        );
        // A smaller region inside a window needs no new one.
        let inner = window_around([101, 51, 102, 52], [1024, 768]);
        let far = window_around([500, 500, 510, 510], [1024, 768]);
        let u = pass(
            &pass(&Uncorrected::default(), &[(20, at)], 0),
            &[(20, inner), (18, far)],
            0,
        );
        assert_eq!((u.windows(19), u.windows(17)), (&[at][..], &[far][..]));
        assert_eq!(u.windows(20), [inner]);
        assert_eq!(u.all_windows().count(), 3);
        let u = u.with_whole([17]);
        assert!(u.whole(17) && u.windows(17).is_empty());
        // The Z correction: the layer below and its held-back layers whole, then the layer.
        let u = pass(&Uncorrected::default(), &[(20, at)], 3);
        assert_eq!(
            (u.whole_layers(), u.all_windows().count()),
            (vec![16, 17, 18, 19], 0)
        );
        let u = pass(&u, &[(20, at)], 3);
        assert_eq!(u.whole_layers(), [16, 17, 18, 19, 20]);
    }

    /// A pin too thin to cure is drawn wider by the correction, but not in a plain window:
    /// there the layer is its coverage before the correction, and nothing is counted as
    /// widened.
    #[test]
    fn a_window_draws_as_off_and_widens_nothing() {
        use crate::cure::shift::Coverage;
        use crate::job::cure_records::CureJob;
        use crate::job::CureOptions;
        use crate::raster::{Rasterizer, Scratch};
        let profile = crate::profile::Profile::default_profile();
        let job = CureJob::new(&profile, &CureOptions::default())
            .unwrap()
            .unwrap();
        let raster = Rasterizer::new(profile.field());
        let p = profile.field().pixel_mm;
        let rect = |c0: f64, r0: f64, c1: f64, r1: f64| {
            let [x0, x1, y0, y1] = [c0 * p, c1 * p, (768.0 - r1) * p, (768.0 - r0) * p];
            vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
        };
        // A 0.3 px pin at column 400, row 300, between two blocks.
        let section = [
            rect(100.0, 100.0, 120.0, 120.0),
            rect(400.6, 300.1, 400.9, 300.4),
            rect(500.0, 400.0, 520.0, 420.0),
        ];
        let own = Coverage::draw(&raster, &section, &mut Scratch::default());
        let corr = job.correction_of((10, 20), (&section, false), &own, &[]);
        let draw = |windows: &[PixelBox]| {
            let s = &mut Scratch::default();
            let c = (None, windows);
            let r = &mut |_: &[usize]| true;
            job.draw(
                &raster,
                &section,
                c,
                corr.as_ref(),
                &[],
                r,
                None,
                false,
                s,
                false,
                None,
            )
        };
        let (_, corrected) = draw(&[]);
        assert_eq!(corrected.widened.map(|w| w.features), Some(1));
        let window = PixelBox::new(290, 310, 390, 410);
        let (m, plain) = draw(&[window]);
        assert!(plain.widened.is_none());
        let off = raster.coverage(&section, &mut Scratch::default());
        let (corrected, _) = draw(&[]);
        let w = m.width as usize;
        for r in 0..m.height as usize {
            for c in 0..w {
                let inside = window.rows().contains(&r) && window.cols().contains(&c);
                let want = if inside { &off } else { &corrected };
                assert_eq!(m.data[r * w + c], want.data[r * w + c], "({r}, {c})");
            }
        }
    }

    #[test]
    fn the_saved_coverage_goes_back_into_its_windows_only() {
        let (w, h) = (8usize, 6usize);
        let data: Vec<u8> = (0..w * h).map(|k| k as u8).collect();
        let m0 = Mask {
            width: w as u32,
            height: h as u32,
            data: data.clone(),
        };
        let windows = [PixelBox::new(1, 3, 2, 5), PixelBox::new(4, 9, 6, 9)];
        let saved = Saved::take(&m0, &windows);
        let mut m = Mask {
            data: vec![0; w * h],
            ..m0
        };
        assert!(saved.put_back(&mut m, None).is_none());
        for r in 0..h {
            for c in 0..w {
                let inside = windows
                    .iter()
                    .any(|b| b.rows().contains(&r) && b.cols().contains(&c));
                let want = if inside { data[r * w + c] } else { 0 };
                assert_eq!(m.data[r * w + c], want, "({r}, {c})");
            }
        }
    }
}
