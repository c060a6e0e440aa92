//! Tracking resolution (Section V-B, Appendices B and C): the closed forms
//! of Theorems 5.3 and 5.5 and the integrals they come from.
//!
//! With N sensors in an a × b field, a group of n_group sensors lies
//! within a circle of radius r = √(n_group·a·b / (πN)) (equation (8)), so
//! its sensing range reaches R + r. For a linear path fragment of length l
//! perpendicular to the line joining two neighbouring groups:
//!
//! - finest resolution (Theorem 5.3): ((R+r)²/(4l))·asin(l/(2(R+r)))
//!   − √((R+r)² − (l/2)²)/8;
//! - average resolution (Theorem 5.5): ((R+r)²/(4l²))·asin(l/(2(R+r)))·
//!   ((R+r) − 2√((R+r)² − (l/2)²)) + 3(R+r)²/(16l) − l/16.
//!
//! Theorem 5.3's closed form is exactly its integral (Appendix B); the
//! tests check it. Theorem 5.5's closed form is *not* the integral printed
//! in Appendix C — for short fragments it is about half of it, and both
//! grow like (R+r)²/l as l → 0 because the appendix normalises by l²
//! instead of by the area integrated over. Both are given here
//! ([`average_resolution`], [`average_resolution_integral`]); the paper's
//! Fig. 9 plots the closed form.

/// r of equation (8): the mean radius of a sensor group.
pub fn group_radius(n_group: usize, a: f64, b: f64, sensors: usize) -> f64 {
    (n_group as f64 * a * b / (std::f64::consts::PI * sensors as f64)).sqrt()
}

/// Theorem 5.3, the finest tracking resolution, metres. `None` unless
/// 0 < l ≤ 2(R + r).
pub(crate) fn finest_resolution(range: f64, r: f64, l: f64) -> Option<f64> {
    let p = range + r;
    if !(l > 0.0 && l <= 2.0 * p) {
        return None;
    }
    Some(p * p / (4.0 * l) * (l / (2.0 * p)).asin() - (p * p - l * l / 4.0).sqrt() / 8.0)
}

/// Theorem 5.5, the average tracking resolution, metres (closed form as
/// printed). `None` unless 0 < l ≤ 2(R + r).
pub fn average_resolution(range: f64, r: f64, l: f64) -> Option<f64> {
    let p = range + r;
    if !(l > 0.0 && l <= 2.0 * p) {
        return None;
    }
    let s = (p * p - l * l / 4.0).sqrt();
    Some(
        p * p / (4.0 * l * l) * (l / (2.0 * p)).asin() * (p - 2.0 * s) + 3.0 * p * p / (16.0 * l)
            - l / 16.0,
    )
}

/// Simpson's rule with `n` (even) intervals.
#[cfg(test)]
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let n = n.max(2) & !1;
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// Appendix B's integral, (1/2)∫₀^{l/2} ((R+r)cos θ₂ − x)/l dy with
/// sin θ₂ = y/(R+r) and x = √((R+r)² − (l/2)²).
#[cfg(test)]
pub(crate) fn finest_resolution_integral(range: f64, r: f64, l: f64) -> Option<f64> {
    let p = range + r;
    if !(l > 0.0 && l <= 2.0 * p) {
        return None;
    }
    let x = (p * p - l * l / 4.0).sqrt();
    Some(
        0.5 * simpson(
            |y| ((p * p - y * y).max(0.0).sqrt() - x) / l,
            0.0,
            l / 2.0,
            2000,
        ),
    )
}

/// Appendix C's integral, (1/2)∫_Z^{R+r}∫₀^{l/2} ((R+r)cos θ₂ − x)/l² dy dx
/// with Z = 2√((R+r)² − (l/2)²), as printed.
#[cfg(test)]
pub(crate) fn average_resolution_integral(range: f64, r: f64, l: f64) -> Option<f64> {
    let p = range + r;
    if !(l > 0.0 && l <= 2.0 * p) {
        return None;
    }
    let z = 2.0 * (p * p - l * l / 4.0).sqrt();
    let inner = |x: f64| {
        simpson(
            |y| ((p * p - y * y).max(0.0).sqrt() - x) / (l * l),
            0.0,
            l / 2.0,
            400,
        )
    };
    Some(0.5 * simpson(inner, z, p, 400))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn theorem_5_3_is_its_integral() {
        for sensors in [400, 700, 1000, 1300] {
            let r = group_radius(10, 1600.0, 1600.0, sensors);
            for l in [3.0, 15.0, 100.0, 300.0] {
                let closed = finest_resolution(250.0, r, l).unwrap();
                let integral = finest_resolution_integral(250.0, r, l).unwrap();
                assert!(
                    (closed - integral).abs() < 1e-6 * (1.0 + closed),
                    "{sensors} {l}: {closed} vs {integral}"
                );
            }
        }
    }

    #[test]
    fn theorem_5_5_values_and_its_discrepancy_with_appendix_c() {
        let r = group_radius(10, 1600.0, 1600.0, 1000);
        assert!((r - 90.27).abs() < 0.01, "{r}");
        let avg = average_resolution(250.0, r, 100.0).unwrap();
        assert!((avg - 68.74).abs() < 0.01, "{avg}");
        // More sensors, smaller groups, finer resolution.
        let r400 = group_radius(10, 1600.0, 1600.0, 400);
        assert!(average_resolution(250.0, r400, 100.0).unwrap() > avg);
        assert!(finest_resolution(250.0, r, 100.0).unwrap() < avg);
        // The closed form is about half the printed integral for short l.
        let integral = average_resolution_integral(250.0, r, 3.0).unwrap();
        let closed = average_resolution(250.0, r, 3.0).unwrap();
        assert!(
            (integral / closed - 2.0).abs() < 0.01,
            "{integral} {closed}"
        );
        assert!(average_resolution(250.0, r, 0.0).is_none());
        assert!(average_resolution(250.0, r, 1000.0).is_none());
    }
}
