//! Sensor deployment (Section II and VI-A): N sensors dropped uniformly at
//! random over the field; their positions are known to the tracker.

use idmesh_sim::{Rect, Vec2};
use rand::Rng;

/// `n` sensor positions drawn uniformly from `field`.
pub(crate) fn deploy_uniform(n: usize, field: Rect, rng: &mut impl Rng) -> Vec<Vec2> {
    (0..n).map(|_| field.sample(rng)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn sensors_fill_the_field() {
        let field = Rect::with_size(1600.0, 1600.0);
        let s = deploy_uniform(1000, field, &mut ChaCha8Rng::seed_from_u64(1));
        assert!(s.iter().all(|p| field.contains(*p)));
        let left = s.iter().filter(|p| p.x < 800.0).count();
        assert!((430..570).contains(&left), "{left}");
    }
}
