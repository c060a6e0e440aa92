//! The rectangular field the synthetic targets move in.

use super::Vec2;
use rand::Rng;

/// An axis-aligned rectangle `[min.x, max.x] × [min.y, max.y]`, in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub min: Vec2,
    pub max: Vec2,
}

impl Rect {
    /// The rectangle `[0, width] × [0, height]`.
    pub fn with_size(width: f64, height: f64) -> Self {
        Rect {
            min: Vec2::ZERO,
            max: Vec2::new(width, height),
        }
    }

    pub fn width(&self) -> f64 {
        self.max.x - self.min.x
    }

    pub fn height(&self) -> f64 {
        self.max.y - self.min.y
    }

    #[cfg(test)]
    pub(crate) fn area(&self) -> f64 {
        self.width() * self.height()
    }

    /// Width and height finite and positive.
    pub(crate) fn is_valid(&self) -> bool {
        self.min.is_finite() && self.max.is_finite() && self.width() > 0.0 && self.height() > 0.0
    }

    pub fn contains(&self, p: Vec2) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }

    /// The rectangle shrunk by `margin` on every side (never below a point:
    /// a margin wider than half the rectangle collapses it to its centre).
    pub fn shrink(&self, margin: f64) -> Rect {
        let mx = margin.min(self.width() / 2.0);
        let my = margin.min(self.height() / 2.0);
        Rect {
            min: Vec2::new(self.min.x + mx, self.min.y + my),
            max: Vec2::new(self.max.x - mx, self.max.y - my),
        }
    }

    /// The nearest point of the rectangle to `p`.
    pub fn clamp(&self, p: Vec2) -> Vec2 {
        Vec2::new(
            p.x.clamp(self.min.x, self.max.x),
            p.y.clamp(self.min.y, self.max.y),
        )
    }

    /// A point drawn uniformly from the rectangle.
    pub fn sample(&self, rng: &mut impl Rng) -> Vec2 {
        Vec2::new(
            self.min.x + rng.gen::<f64>() * self.width(),
            self.min.y + rng.gen::<f64>() * self.height(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn shrink_clamp_sample() {
        let r = Rect::with_size(10.0, 4.0);
        assert!(r.is_valid());
        assert_eq!(r.area(), 40.0);
        let s = r.shrink(3.0);
        assert_eq!(s.min, Vec2::new(3.0, 2.0));
        assert_eq!(s.max, Vec2::new(7.0, 2.0));
        assert_eq!(r.clamp(Vec2::new(-1.0, 9.0)), Vec2::new(0.0, 4.0));
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..100 {
            assert!(r.contains(r.sample(&mut rng)));
        }
        assert!(!Rect::with_size(0.0, 1.0).is_valid());
    }
}
