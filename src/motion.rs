//! Trapezoidal motion: the time a stage needs for a move under speed and acceleration
//! limits. Shared by the planner's estimates and the executor's simulation (pure math,
//! no knowledge of either).

/// Time to travel `dist` mm starting and ending at rest, with cruise speed `v` mm/s and
/// acceleration/deceleration `a` mm/s² (a triangular profile when `dist` is too short to
/// reach `v`).
///
/// ```
/// // 10 mm at 2 mm/s with 4 mm/s²: 0.5 s to accelerate, 0.5 s to stop, 9 mm cruising.
/// assert!((dmdsl::motion::move_time(10.0, 2.0, 4.0) - 5.5).abs() < 1e-12);
/// ```
pub fn move_time(dist: f64, v: f64, a: f64) -> f64 {
    let d = dist.abs();
    if d == 0.0 {
        return 0.0;
    }
    let d_acc = v * v / a; // distance spent accelerating plus decelerating
    if d >= d_acc {
        2.0 * v / a + (d - d_acc) / v
    } else {
        2.0 * (d / a).sqrt()
    }
}

/// Position after `t` seconds of a move from `from` to `to` (same profile as
/// [`move_time`]); clamps to `to` after the move ends.
pub fn position_at(from: f64, to: f64, v: f64, a: f64, t: f64) -> f64 {
    let d = (to - from).abs();
    let sign = if to >= from { 1.0 } else { -1.0 };
    let total = move_time(d, v, a);
    if t <= 0.0 {
        return from;
    }
    if t >= total {
        return to;
    }
    let vp = if d >= v * v / a { v } else { (a * d).sqrt() };
    let ta = vp / a;
    let s = if t < ta {
        0.5 * a * t * t
    } else if t <= total - ta {
        0.5 * a * ta * ta + vp * (t - ta)
    } else {
        let tr = total - t;
        d - 0.5 * a * tr * tr
    };
    from + sign * s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_and_triangle() {
        // 10 mm at 2 mm/s, 4 mm/s²: accel 0.5 s over 0.5 mm each end; cruise 9 mm / 2 = 4.5 s.
        assert!((move_time(10.0, 2.0, 4.0) - 5.5).abs() < 1e-12);
        // 0.5 mm: triangle, peak sqrt(a·d) = 1.414 mm/s, t = 2·sqrt(d/a).
        assert!((move_time(0.5, 2.0, 4.0) - 2.0 * (0.125f64).sqrt()).abs() < 1e-12);
        assert_eq!(move_time(0.0, 1.0, 1.0), 0.0);
        let t = move_time(10.0, 2.0, 4.0);
        assert!((position_at(0.0, 10.0, 2.0, 4.0, t / 2.0) - 5.0).abs() < 1e-9);
        assert_eq!(position_at(3.0, -1.0, 2.0, 4.0, 100.0), -1.0);
        assert!((position_at(3.0, -1.0, 2.0, 4.0, 0.5) - 2.5).abs() < 1e-12);
    }
}
