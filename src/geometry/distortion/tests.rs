//! Tests of the fit and the pre-warp on synthetic lenses (barrel or pincushion, keystone,
//! local bumps, noise) whose forward map is known.

use super::table::Pair;
use super::warp::lerp;
use super::*;

const W: f64 = 65.0;
const H: f64 = 48.75;
const P: f64 = 65.0 / 1024.0;

/// Tiny deterministic PRNG (xorshift64*), Gaussian by Box–Muller.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let u = self.next().max(1e-300);
        let v = self.next();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Forward map: barrel (k < 0) about the centre plus mild keystone, plus bumps.
fn forward(p: [f64; 2], k: f64, bumps: f64) -> [f64; 2] {
    let (cx, cy) = (W / 2.0, H / 2.0);
    let (dx, dy) = (p[0] - cx, p[1] - cy);
    let r2 = (dx * dx + dy * dy) / (cx * cx + cy * cy);
    let s = 1.0 + k * r2;
    let key = 1.0 + 0.01 * dy / cy;
    // Local "assembly" errors: two Gaussian bumps of ~8 mm radius.
    let g = |c: [f64; 2]| {
        let d2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
        (-d2 / (2.0 * 8.0 * 8.0)).exp()
    };
    let bx = bumps * (g([20.0, 30.0]) - g([45.0, 15.0]));
    let by = bumps * (g([45.0, 15.0]) + 0.5 * g([15.0, 12.0]));
    [cx + dx * s * key + bx, cy + dy * s + by]
}

fn table(k: f64, bumps: f64, noise: f64, seed: u64) -> Table {
    let mut rng = Rng(seed);
    let mut pairs = Vec::new();
    let mut line = 1;
    for j in 0..=9 {
        for i in 0..=13 {
            let aim = [i as f64 * W / 13.0, j as f64 * H / 9.0];
            let s = forward(aim, k, bumps);
            line += 1;
            pairs.push(Pair {
                aim,
                seen: [s[0] + noise * rng.gauss(), s[1] + noise * rng.gauss()],
                line,
            });
        }
    }
    Table {
        origin: "t.csv".into(),
        unit: "line",
        source: "t.csv".into(),
        sha256: String::new(),
        pairs,
    }
}

fn landing_error(c: &Correction, k: f64, bumps: f64) -> (f64, f64) {
    let mut w = c.warper();
    let (mut s, mut mx, mut n) = (0.0, 0.0f64, 0);
    for j in 0..20 {
        for i in 0..26 {
            let t = [6.0 + i as f64 * 2.1, 6.0 + j as f64 * 1.9];
            let l = forward(w.aim(t), k, bumps);
            let e = (l[0] - t[0]).hypot(l[1] - t[1]);
            s += e * e;
            mx = mx.max(e);
            n += 1;
        }
    }
    ((s / n as f64).sqrt(), mx)
}

#[test]
fn fit_errors_name_the_line() {
    let mut t = table(0.0, 0.0, 0.0, 1);
    t.pairs.truncate(5);
    let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
    assert!(e.contains("at least 6 points, found 5"), "{e}");
    let mut t = table(0.0, 0.0, 0.0, 1);
    t.pairs[7].aim = [70.0, 1.0];
    let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
    assert_eq!(
        e,
        "t.csv: line 9: x_mm,y_mm = (70, 1) is outside the projector field 0..65 x 0..48.75 mm"
    );
    let mut t = table(0.0, 0.0, 0.0, 1);
    t.pairs[9].seen = t.pairs[3].seen;
    let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
    assert!(e.starts_with("t.csv: line 11: same seen point"), "{e}");
    assert!(e.ends_with("as line 5"), "{e}");
    let mut t = table(0.0, 0.0, 0.0, 1);
    for (i, p) in t.pairs.iter_mut().enumerate() {
        p.seen = [i as f64, 2.0 * i as f64];
    }
    let e = Correction::fit(&t, [W, H], P).unwrap_err().to_string();
    assert!(e.contains("collinear"), "{e}");
}

#[test]
fn exact_table_gives_exact_inverse() {
    // 1 % keystone only, no noise: a degree-5 polynomial inverts it to ~1e-9 mm.
    let t = table(0.0, 0.0, 0.0, 1);
    let c = Correction::fit(&t, [W, H], P).unwrap();
    let r = c.report();
    assert!(r.poly_max_mm < 1e-8 && r.cv_max_mm < 1e-8, "{r:?}");
    assert!(
        r.cv_rms_mm.is_finite() && r.residual_weight.is_finite(),
        "{r:?}"
    );
    let mut w = c.warper();
    for p in [[1.0, 1.0], [10.0, 7.5], [64.0, 48.0]] {
        let a = forward(w.aim(p), 0.0, 0.0);
        assert!(
            (a[0] - p[0]).abs() < 1e-7 && (a[1] - p[1]).abs() < 1e-7,
            "{p:?} -> {a:?}"
        );
    }
}

#[test]
fn smooth_noisy_distortion_is_averaged_not_interpolated() {
    // Barrel + keystone (corners ~2 mm off), noise 0.01 mm, no assembly bumps: the
    // polynomial carries it; κ stays small because residuals are noise.
    let k = -0.05;
    let t = table(k, 0.0, 0.01, 7);
    let c = Correction::fit(&t, [W, H], P).unwrap();
    let r = c.report();
    assert!(r.max_correction_mm > 1.5, "{r:?}");
    assert!(r.residual_weight < 0.3, "{r:?}");
    let (rms, max) = landing_error(&c, k, 0.0);
    assert!(rms < 0.01 && max < 0.025, "rms {rms} max {max}");
    // Pure interpolation of the same table passes the noise through: worse.
    let mut pure = Correction::fit(&t, [W, H], P).unwrap();
    pure.kappa = 1.0;
    let (rms1, _) = landing_error(&pure, k, 0.0);
    assert!(rms1 > rms * 1.3, "interpolated {rms1} vs fitted {rms}");
}

#[test]
fn assembly_errors_are_interpolated() {
    // Bumps of 0.15 mm the polynomial cannot describe: the residual interpolant picks
    // them up (κ near 1) and the landing error drops well below the polynomial's.
    let k = 0.04;
    let t = table(k, 0.15, 0.005, 3);
    let c = Correction::fit(&t, [W, H], P).unwrap();
    let r = c.report();
    assert!(r.residual_weight > 0.7, "{r:?}");
    let (rms, max) = landing_error(&c, k, 0.15);
    let mut poly_only = Correction::fit(&t, [W, H], P).unwrap();
    poly_only.kappa = 0.0;
    let (rms0, _) = landing_error(&poly_only, k, 0.15);
    assert!(
        rms < 0.6 * rms0,
        "with residual {rms}, polynomial only {rms0}"
    );
    assert!(max < 0.12, "max {max}");
}

#[test]
fn densified_warp_stays_within_sag() {
    // With (κ ≈ 1) and without (κ = 0) the residual interpolant; long random edges (the
    // midpoint refinement) and short circle edges (the curvature-bound shortcut).
    for (k, bumps) in [(-0.06, 0.1), (0.08, 0.0)] {
        let t = table(k, bumps, 0.0, 5);
        let c = Correction::fit(&t, [W, H], P).unwrap();
        let mut rng = Rng(11);
        for n in 0..24 {
            let a = [8.0 + 49.0 * rng.next(), 8.0 + 32.0 * rng.next()];
            let contour: Contour = if n % 2 == 0 {
                let b = [8.0 + 49.0 * rng.next(), 8.0 + 32.0 * rng.next()];
                let m = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0 + 0.01];
                vec![a, b, m]
            } else {
                (0..64)
                    .map(|i| {
                        let t = i as f64 / 64.0 * std::f64::consts::TAU;
                        [a[0] + 3.0 * t.cos(), a[1] + 3.0 * t.sin()]
                    })
                    .collect()
            };
            let mut w = c.warper();
            let out = w.warp(std::slice::from_ref(&contour)).unwrap();
            let poly = &out[0];
            // Every point of every warped edge lies within SAG_PX of the polyline.
            for i in 0..contour.len() {
                let (a, b) = (contour[i], contour[(i + 1) % contour.len()]);
                for s in 0..=16 {
                    let q = w.aim(lerp(a, b, s as f64 / 16.0));
                    let d = (0..poly.len())
                        .map(|j| seg_dist(q, poly[j], poly[(j + 1) % poly.len()]))
                        .fold(f64::INFINITY, f64::min);
                    assert!(d <= SAG_PX * P * 1.01, "k {k}: sag {} px", d / P);
                }
            }
        }
    }
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a[0] + t * dx - p[0]).hypot(a[1] + t * dy - p[1])
}

#[test]
fn unreachable_target_is_reported() {
    // Barrel: light is pulled towards the centre, so near the corners the projector would
    // have to aim outside its field.
    let t = table(-0.05, 0.0, 0.0, 1);
    let c = Correction::fit(&t, [W, H], P).unwrap();
    let sq = vec![[0.2, 0.2], [3.0, 0.2], [3.0, 3.0], [0.2, 3.0]];
    let e = c
        .warp_section(&[sq], Path::new("part.stl"), 4)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("part.stl: layer 4: build-plane point (0.200, 0.200) mm cannot be reached"),
        "{e}"
    );
    let ok = vec![[20.0, 20.0], [23.0, 20.0], [23.0, 23.0], [20.0, 23.0]];
    assert!(c.warp_section(&[ok], Path::new("part.stl"), 4).is_ok());
}

#[test]
fn only_a_layers_own_warp_counts_its_extrapolated_points() {
    // A table measured over the middle of the field only: a square near the corner lies
    // outside the area it measured, but within the projector's reach.
    let mut t = table(0.0, 0.0, 0.0, 1);
    t.pairs
        .retain(|p| (10.0..=55.0).contains(&p.aim[0]) && (10.0..=40.0).contains(&p.aim[1]));
    let c = Correction::fit(&t, [W, H], P).unwrap();
    let sq = vec![[2.0, 2.0], [5.0, 2.0], [5.0, 5.0], [2.0, 5.0]];
    let model = Path::new("part.stl");
    // Looked at by other layers (or the prediction) as often as may be: not counted.
    for _ in 0..3 {
        c.warp_section(std::slice::from_ref(&sq), model, 4).unwrap();
    }
    assert_eq!(c.report().extrapolated_points, 0);
    c.warp_layer(std::slice::from_ref(&sq), model, 4).unwrap();
    let once = c.report().extrapolated_points;
    assert!(once >= 4, "{once}");
    c.warp_layer(&[sq], model, 5).unwrap();
    assert_eq!(c.report().extrapolated_points, 2 * once);
}
