//! Known light fields P(x, y) and responses S(g) with a fixed-seed noise generator: the
//! synthetic calibration sets of `calibrate` and `calibrate_sweep` (a field only the sweep
//! uses lives there), with the published model of `src/optics/synthetic.rs`.

#[path = "../../src/optics/synthetic.rs"]
mod published;
pub use published::{p_published, s_published};

/// A seeded random number generator: splitmix64 for uniform numbers, Box–Muller for
/// normal ones.
pub struct Rng(pub u64);
impl Rng {
    /// A uniform number in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    /// A standard normal number.
    pub fn normal(&mut self) -> f64 {
        let (a, b) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }
}

/// A light field P(x, y), x and y in mm from the field's bottom-left corner.
pub type FieldFn = fn(f64, f64) -> f64;
/// A gray response S(g), g the pixel value.
pub type ResponseFn = fn(f64) -> f64;

/// A smooth cubic field, 1.5 : 1.
pub fn p_cubic(x: f64, y: f64) -> f64 {
    1.0 + 0.02 * x - 0.01 * y - 0.0004 * x * x + 0.0002 * x * y + 0.0003 * y * y + 2e-6 * x * x * x
        - 3e-6 * y * y * y
}
/// A Gaussian beam off centre with a tilt, 3.7 : 1.
pub fn p_gauss(x: f64, y: f64) -> f64 {
    2.0 * (-((x - 40.0).powi(2) + (y - 20.0).powi(2)) / (2.0 * 30.0f64.powi(2))).exp()
        * (1.0 + 0.004 * y)
}
/// A vignette (1 + r²/50²)⁻² about the field centre, 2.7 : 1 (not a polynomial, nor the
/// exponential of one).
pub fn p_vignette(x: f64, y: f64) -> f64 {
    let r2 = (x - 32.5).powi(2) + (y - 24.375).powi(2);
    (1.0 + r2 / 2500.0).powi(-2)
}
/// A gamma-2.2 response (steps of 0.9–1.9 % over the grays used).
pub fn s_gamma(g: f64) -> f64 {
    (g / 255.0).powf(2.2)
}

/// The gray levels every synthetic set is measured at.
pub const GRAYS: [u32; 7] = [255, 235, 215, 195, 175, 155, 135];

/// (max − min) / mean of `v`, %.
pub fn spread(v: &[f64]) -> f64 {
    let lo = v.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    (hi - lo) / (v.iter().sum::<f64>() / v.len() as f64) * 100.0
}

/// (zone-mean spread, per-pixel spread) of irradiance samples `(x_mm, y_mm, E)` over the
/// calibrated 65 × 45 mm area: means of the 13 × 9 zones of 5 mm, and every sample there.
pub fn zone_and_pixel_spreads(e: impl IntoIterator<Item = (f64, f64, f64)>) -> (f64, f64) {
    let mut sum = [[0.0f64; 13]; 9];
    let mut n = [[0usize; 13]; 9];
    let mut inside = Vec::new();
    for (x, y, v) in e {
        if y <= 45.0 {
            let (zc, zr) = ((x / 5.0) as usize, (y / 5.0) as usize);
            sum[zr][zc] += v;
            n[zr][zc] += 1;
            inside.push(v);
        }
    }
    let means: Vec<f64> = (0..9)
        .flat_map(|r| (0..13).map(move |c| (r, c)))
        .map(|(r, c)| sum[r][c] / n[r][c] as f64)
        .collect();
    (spread(&means), spread(&inside))
}

/// Readings `(x_mm, y_mm, gray, irradiance)` at the 13 × 9 zone centres (5 mm zones from
/// the bottom-left corner) for every gray of [`GRAYS`], with relative normal noise.
pub fn centre_readings(
    p: FieldFn,
    s: ResponseFn,
    noise: f64,
    seed: u64,
) -> Vec<(f64, f64, u32, f64)> {
    let mut rng = Rng(seed);
    let mut out = Vec::new();
    for g in GRAYS {
        for i in 0..13 {
            for j in 0..9 {
                let (x, y) = (2.5 + 5.0 * i as f64, 2.5 + 5.0 * j as f64);
                out.push((
                    x,
                    y,
                    g,
                    p(x, y) * s(g as f64) * (1.0 + noise * rng.normal()),
                ));
            }
        }
    }
    out
}
