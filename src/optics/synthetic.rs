//! The published model of Xu et al. 2010 as formulas: the calibration the default profile
//! carries as data. Test code only: the library's tests and `tests/it/synthetic.rs` (which
//! includes this file by path) compare against it.

/// The published P of Xu et al. 2010 (x, y in cm), 5.6 : 1 (the built-in default profile
/// carries the same cubic as data).
pub fn p_published(x: f64, y: f64) -> f64 {
    let (x, y) = (x / 10.0, y / 10.0);
    -1.1 * x * x * x - 0.8 * y * y * y
        + 0.8 * x * y * y
        + 0.05 * x * x * y
        + 11.5 * x * x
        + 12.5 * y * y
        - 2.8 * x * y
        - 0.3 * x
        - 63.6 * y
        + 161.8
}
/// The published S of Xu et al. 2010 with z = 255 − pixel value (steps of 2–3 % near its
/// operating point).
pub fn s_published(g: f64) -> f64 {
    let z = 255.0 - g;
    -1e-6 * z * z * z + 5.78e-4 * z * z - 0.101 * z + 5.72
}
