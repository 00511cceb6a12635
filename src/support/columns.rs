//! From a point down: a support's head, its pillar and its foot, on the pad or on the part.
//!
//! The pillar goes straight down from the head. Below the head it never meets the part:
//! looking down layer by layer, the first layer of the part within the pillar's radius
//! (plus a pixel) below the head, or on the head's axis within the head, is where the
//! support stands, on a reversed head reaching into that layer; with none, it stands on
//! the pad on a base cone. Within the head only the axis counts: a head under a surface
//! sloping down beside it touches that surface, as a head must.

use super::points::Point;
use super::runs::{self, Run};

/// The shapes of a support, in mm.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    /// Pixel edge, mm.
    pub pixel_mm: f64,
    /// Layer height, mm.
    pub layer_mm: f64,
    /// Head radius at the contact.
    pub contact_r: f64,
    /// Pillar radius (before thickening).
    pub pillar_r: f64,
    /// Radius of the base cone on the pad.
    pub base_r: f64,
    /// Head length (its cone).
    pub head_len: f64,
    /// Head penetration into the part.
    pub penetration: f64,
    /// Base cone height.
    pub base_len: f64,
    /// Top of the pad.
    pub pad_top: f64,
    /// Longest pillar before thickening.
    pub max_len: f64,
}

/// What a support stands on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Foot {
    /// The pad.
    Pad,
    /// The part, on this layer of it: on a reversed head where the layer is lit under the
    /// axis (`true`), else on the pillar's end widened by a pixel and a half so that it
    /// shares pixels with the part beside the axis.
    Part(usize, bool),
}

/// One support: its point, what it stands on and its profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// The point it holds.
    pub point: Point,
    /// What it stands on.
    pub foot: Foot,
    /// Its pillar's diameter (thickened when long), mm.
    pub pillar_diameter_mm: f64,
    /// Its profile from the bottom up: (z, radius) in mm, z strictly increasing.
    pub rings: Vec<[f64; 2]>,
}

impl Column {
    /// Height of its foot (the pad's top, or the top of the layer it stands on), mm.
    pub fn foot_z(&self, s: &Shape) -> f64 {
        match self.foot {
            Foot::Pad => s.pad_top,
            Foot::Part(k, _) => (k + 1) as f64 * s.layer_mm,
        }
    }
}

/// The support of `p` in a part of lit pixels `masks` per layer (from layer `first`).
pub fn column(p: Point, masks: &[Vec<Run>], first: usize, s: &Shape) -> Column {
    let foot = landing(p, masks, first, s);
    let zc = p.layer as f64 * s.layer_mm;
    let (z0, foot_len) = match foot {
        Foot::Pad => (s.pad_top, s.base_len),
        Foot::Part(k, true) => ((k + 1) as f64 * s.layer_mm, s.head_len),
        Foot::Part(k, false) => ((k + 1) as f64 * s.layer_mm, s.layer_mm / 4.0),
    };
    let avail = zc - z0;
    let pillar = (avail - foot_len - s.head_len).max(0.0);
    let r = s.pillar_r * (pillar / s.max_len).sqrt().max(1.0);
    // Both cones shortened alike when the gap is shorter than the two.
    let f = (avail / (foot_len + s.head_len)).min(1.0);
    // A foot on the part reaches into the layer it stands on by the penetration, and no
    // lower: what reached below the part's top there might hang in the air. A point right
    // above that layer has no layer between: its contact goes into that layer (¾ of it).
    let into = if avail < s.layer_mm / 2.0 {
        z0 - 0.75 * s.layer_mm
    } else {
        z0 - s.penetration.min(0.75 * s.layer_mm)
    };
    let mut rings = match foot {
        Foot::Pad if s.base_len > 0.0 => vec![[z0, s.base_r.max(r)], [z0 + foot_len * f, r]],
        Foot::Pad => vec![[z0, r]],
        Foot::Part(_, true) => vec![
            [into, s.contact_r],
            [z0, s.contact_r],
            [z0 + foot_len * f, r],
        ],
        Foot::Part(_, false) => {
            // Beside the axis the part is a pixel or so outside the pillar: the widened end
            // reaches into that layer (¾ of it) to share its pixels, whatever the
            // penetration.
            let wide = r + 2.5 * s.pixel_mm;
            vec![[z0 - 0.75 * s.layer_mm, wide], [z0 + foot_len * f, r]]
        }
    };
    rings.extend([
        [zc - s.head_len * f, r],
        [zc, s.contact_r],
        [zc + s.penetration, s.contact_r],
    ]);
    rings.dedup_by(|b, a| b[0] - a[0] < 1e-9);
    Column {
        point: p,
        foot,
        pillar_diameter_mm: 2.0 * r,
        rings,
    }
}

/// What the support of `p` stands on.
fn landing(p: Point, masks: &[Vec<Run>], first: usize, s: &Shape) -> Foot {
    let (cx, cy) = (p.col_row[0] as f64 + 0.5, p.col_row[1] as f64 + 0.5);
    let zc = p.layer as f64 * s.layer_mm;
    for k in (first..p.layer).rev() {
        let z = (k as f64 + 0.5) * s.layer_mm;
        let t = zc - z;
        let r_mm = if t <= s.head_len {
            s.contact_r / 2.0
        } else if z < s.pad_top + s.base_len {
            let u = (z - s.pad_top) / s.base_len;
            s.pillar_r + (s.base_r - s.pillar_r) * (1.0 - u)
        } else {
            s.pillar_r
        };
        if runs::any_within(&masks[k], cx, cy, r_mm / s.pixel_mm + 1.0) {
            let under = runs::any_within(&masks[k], cx, cy, s.contact_r / s.pixel_mm / 2.0);
            return Foot::Part(k, under);
        }
    }
    Foot::Pad
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> Shape {
        Shape {
            pixel_mm: 0.1,
            layer_mm: 0.1,
            contact_r: 0.2,
            pillar_r: 0.5,
            base_r: 1.5,
            head_len: 1.0,
            penetration: 0.2,
            base_len: 1.0,
            pad_top: 1.0,
            max_len: 15.0,
        }
    }

    fn point(layer: usize) -> Point {
        Point {
            col_row: [50, 50],
            layer,
            island: true,
        }
    }

    #[test]
    fn a_support_over_nothing_stands_on_the_pad() {
        let masks = vec![Vec::new(); 80];
        let c = column(point(70), &masks, 0, &shape());
        assert_eq!(c.foot, Foot::Pad);
        let zs: Vec<f64> = c.rings.iter().map(|r| r[0]).collect();
        for (z, want) in zs.iter().zip([1.0, 2.0, 6.0, 7.0, 7.2]) {
            assert!((z - want).abs() < 1e-9, "{zs:?}");
        }
        assert_eq!(c.pillar_diameter_mm, 1.0);
    }

    #[test]
    fn a_support_over_the_part_stands_on_it_and_long_pillars_thicken() {
        // A block at layers 20..30 under the point (pixels 45..55), a shelf beside the axis
        // at layers 60..69 (within the head's reach only off the axis).
        let mut masks = vec![Vec::new(); 80];
        for m in &mut masks[20..30] {
            *m = (45..55).map(|r| [r, 45, 55]).collect();
        }
        for m in &mut masks[62..69] {
            *m = (40..60).map(|r| [r, 53, 60]).collect();
        }
        let c = column(point(70), &masks, 0, &shape());
        assert_eq!(c.foot, Foot::Part(29, true));
        assert!(
            (c.rings[0][0] - 2.925).abs() < 1e-9 && c.rings[0][1] == 0.2,
            "{:?}",
            c.rings
        );
        let tall = vec![Vec::new(); 400];
        let c = column(point(390), &tall, 0, &shape());
        // 39 mm up, a 36 mm pillar: √(36 / 15) times as thick.
        assert!((c.pillar_diameter_mm - (36.0f64 / 15.0).sqrt()).abs() < 1e-9);
    }

    #[test]
    fn a_short_gap_shortens_both_cones_alike() {
        let mut masks = vec![Vec::new(); 50];
        masks[30] = (45..55).map(|r| [r, 45, 55]).collect();
        let c = column(point(32), &masks, 0, &shape());
        assert_eq!(c.foot, Foot::Part(30, true));
        // Foot at 3.1, contact at 3.2: the two cones meet half-way.
        let zs: Vec<f64> = c.rings.iter().map(|r| r[0]).collect();
        assert_eq!(zs.len(), 5, "{zs:?}");
        assert!((zs[2] - 3.15).abs() < 1e-9, "{zs:?}");
        assert!(zs.windows(2).all(|w| w[1] > w[0]));
        // A point right above the layer it stands on: its contact reaches into that layer
        // (and up into the point's layer by the penetration).
        let c = column(point(31), &masks, 0, &shape());
        assert_eq!(c.foot, Foot::Part(30, true));
        let want = [[3.025, 0.2], [3.1, 0.2], [3.3, 0.2]];
        assert_eq!(c.rings.len(), 3, "{:?}", c.rings);
        for (got, want) in c.rings.iter().zip(want) {
            assert!(
                (got[0] - want[0]).abs() < 1e-9 && got[1] == want[1],
                "{:?}",
                c.rings
            );
        }
        // The part beside the axis only: the pillar's end, widened, into layer 30.
        masks[30] = (45..55).map(|r| [r, 54, 60]).collect();
        let c = column(point(45), &masks, 0, &shape());
        assert_eq!(c.foot, Foot::Part(30, false));
        assert!(
            (c.rings[0][0] - 3.025).abs() < 1e-9 && (c.rings[0][1] - 0.75).abs() < 1e-9,
            "{:?}",
            c.rings
        );
    }
}
