//! A point or vector on the ground plane, in metres.

use std::ops::{Add, AddAssign, Mul, Neg, Sub, SubAssign};

/// A point or vector on the ground plane, in metres.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Vec2 {
    pub x: f64,
    pub y: f64,
}

impl Vec2 {
    pub const ZERO: Vec2 = Vec2 { x: 0.0, y: 0.0 };

    pub const fn new(x: f64, y: f64) -> Self {
        Vec2 { x, y }
    }

    pub fn dot(self, other: Vec2) -> f64 {
        self.x * other.x + self.y * other.y
    }

    pub fn norm_sq(self) -> f64 {
        self.dot(self)
    }

    pub fn norm(self) -> f64 {
        self.norm_sq().sqrt()
    }

    pub fn distance(self, other: Vec2) -> f64 {
        (self - other).norm()
    }

    pub fn distance_sq(self, other: Vec2) -> f64 {
        (self - other).norm_sq()
    }

    /// The unit vector along `self`, or zero for a (near) zero vector.
    pub fn normalized(self) -> Vec2 {
        let n = self.norm();
        if n > 1e-12 {
            self * (1.0 / n)
        } else {
            Vec2::ZERO
        }
    }

    /// `self` shortened to length `max` if it is longer.
    pub fn clamp_norm(self, max: f64) -> Vec2 {
        let n = self.norm();
        if n > max && n > 0.0 {
            self * (max / n)
        } else {
            self
        }
    }

    /// Linear interpolation: `self` at `s = 0`, `other` at `s = 1`.
    pub fn lerp(self, other: Vec2, s: f64) -> Vec2 {
        self + (other - self) * s
    }

    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl AddAssign for Vec2 {
    fn add_assign(&mut self, o: Vec2) {
        self.x += o.x;
        self.y += o.y;
    }
}

impl Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl SubAssign for Vec2 {
    fn sub_assign(&mut self, o: Vec2) {
        self.x -= o.x;
        self.y -= o.y;
    }
}

impl Mul<f64> for Vec2 {
    type Output = Vec2;
    fn mul(self, s: f64) -> Vec2 {
        Vec2::new(self.x * s, self.y * s)
    }
}

impl Neg for Vec2 {
    type Output = Vec2;
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_and_norms() {
        let a = Vec2::new(3.0, 4.0);
        assert_eq!(a.norm(), 5.0);
        assert_eq!(a.distance(Vec2::ZERO), 5.0);
        assert!(a.normalized().distance(Vec2::new(0.6, 0.8)) < 1e-15);
        assert_eq!(Vec2::ZERO.normalized(), Vec2::ZERO);
        assert!(a.clamp_norm(2.5).distance(Vec2::new(1.5, 2.0)) < 1e-15);
        assert_eq!(a.clamp_norm(10.0), a);
        assert_eq!(Vec2::ZERO.lerp(a, 0.5), Vec2::new(1.5, 2.0));
        assert_eq!(a - a + a * 2.0, Vec2::new(6.0, 8.0));
    }
}
