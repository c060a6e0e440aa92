//! Where the targets go: one position per signal sample.
//!
//! - Random paths (Section VI-A, "paths followed by targets are generated
//!   randomly") come from the scenario generator's random-waypoint model
//!   (`idmesh_sim::waypoint`) stepped once per sample, with speeds in
//!   metres per sample (the paper's "below 0.15 m per sample interval") and
//!   no pauses, inside the central target area.
//! - Zigzag paths (Section VI-J, Fig. 15): from A to B, 300 m apart, a
//!   triangle wave 100 m wide with a given number of periods, walked at the
//!   constant speed that finishes it within the run — so more periods mean
//!   a longer path and a faster target, as in the paper.

use idmesh_sim::Motion;
use idmesh_sim::{Rect, Vec2};
use idmesh_sim::{Waypoint, WaypointParams};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// How target paths are generated.
#[derive(Debug, Clone, PartialEq)]
pub enum PathSpec {
    /// Random waypoint legs, speed drawn per leg uniformly from
    /// `speed` (m/sample); `(v, v)` fixes it (Fig. 9 uses 0.03).
    Random { speed: (f64, f64) },
    /// Zigzag paths of `periods` periods between two points `length` apart,
    /// `width` wide (Fig. 15: 300 m and 100 m).
    Zigzag {
        periods: u32,
        length: f64,
        width: f64,
    },
}

impl Default for PathSpec {
    fn default() -> Self {
        PathSpec::Random {
            speed: (0.05, 0.15),
        }
    }
}

impl PathSpec {
    pub fn validate(&self, area: Rect) -> Result<(), String> {
        match *self {
            PathSpec::Random { speed } => WaypointParams {
                speed,
                pause: (0.0, 0.0),
            }
            .validate(),
            PathSpec::Zigzag {
                periods,
                length,
                width,
            } => {
                if periods == 0
                    || !(length.is_finite() && length > 0.0)
                    || !(width.is_finite() && width >= 0.0)
                {
                    return Err(format!(
                        "zigzag needs ≥ 1 period, length > 0 and width ≥ 0 (got {periods}, {length}, {width})"
                    ));
                }
                if length + width > area.width().min(area.height()) {
                    return Err(format!(
                        "a zigzag {length} m long and {width} m wide does not fit the {} m × {} m target area",
                        area.width(),
                        area.height()
                    ));
                }
                Ok(())
            }
        }
    }
}

/// The ground-truth path of one target: its position at every sample.
#[derive(Debug, Clone, PartialEq)]
pub struct TruePath {
    pub positions: Vec<Vec2>,
}

impl TruePath {
    /// Length walked, metres.
    pub(crate) fn length(&self) -> f64 {
        self.positions.windows(2).map(|w| w[0].distance(w[1])).sum()
    }

    /// Mean speed, metres per sample.
    pub(crate) fn mean_speed(&self) -> f64 {
        self.length() / (self.positions.len().saturating_sub(1)).max(1) as f64
    }
}

/// `count` paths of `samples` positions inside `area`.
pub(crate) fn generate(
    spec: &PathSpec,
    count: usize,
    samples: usize,
    area: Rect,
    rng: &mut ChaCha8Rng,
) -> Vec<TruePath> {
    match *spec {
        PathSpec::Random { speed } => {
            let params = WaypointParams {
                speed,
                pause: (0.0, 0.0),
            };
            let seed: u64 = rng.gen();
            let mut motion = Waypoint::new(
                count,
                area,
                1.0,
                params,
                rand::SeedableRng::seed_from_u64(seed),
            );
            let mut paths: Vec<Vec<Vec2>> = vec![Vec::with_capacity(samples); count];
            for t in 0..samples {
                if t > 0 {
                    motion.advance();
                }
                for (i, p) in motion.positions().iter().enumerate() {
                    // Waypoint targets are always present.
                    paths[i].push(p.unwrap_or_default());
                }
            }
            paths
                .into_iter()
                .map(|positions| TruePath { positions })
                .collect()
        }
        PathSpec::Zigzag {
            periods,
            length,
            width,
        } => (0..count)
            .map(|_| zigzag(periods, length, width, samples, area, rng))
            .collect(),
    }
}

/// One zigzag at a random place and heading that fits inside `area`.
fn zigzag(
    periods: u32,
    length: f64,
    width: f64,
    samples: usize,
    area: Rect,
    rng: &mut ChaCha8Rng,
) -> TruePath {
    let half = width / 2.0;
    // Shrink by the half width so the excursions stay inside too.
    let inner = area.shrink(half);
    let (a, dir) = loop {
        let a = inner.sample(rng);
        let angle = rng.gen::<f64>() * std::f64::consts::TAU;
        let dir = Vec2::new(angle.cos(), angle.sin());
        if inner.contains(a + dir * length) {
            break (a, dir);
        }
    };
    let perp = Vec2::new(-dir.y, dir.x);
    // Corners of the triangle wave: at quarter periods the offset is ±half.
    let quarters = 4 * periods as usize;
    let corners: Vec<Vec2> = (0..=quarters)
        .map(|q| {
            let s = length * q as f64 / quarters as f64;
            let offset = match q % 4 {
                0 | 2 => 0.0,
                1 => half,
                _ => -half,
            };
            a + dir * s + perp * offset
        })
        .collect();
    TruePath {
        positions: walk_polyline(&corners, samples),
    }
}

/// `samples` points evenly spaced by arc length along a polyline.
fn walk_polyline(corners: &[Vec2], samples: usize) -> Vec<Vec2> {
    let total: f64 = corners.windows(2).map(|w| w[0].distance(w[1])).sum();
    let step = if samples > 1 {
        total / (samples - 1) as f64
    } else {
        0.0
    };
    let mut out = Vec::with_capacity(samples);
    let mut leg = 0;
    let mut leg_start = 0.0;
    for k in 0..samples {
        let s = (k as f64 * step).min(total);
        while leg + 2 < corners.len() && leg_start + corners[leg].distance(corners[leg + 1]) < s {
            leg_start += corners[leg].distance(corners[leg + 1]);
            leg += 1;
        }
        let len = corners[leg].distance(corners[leg + 1]);
        let f = if len > 0.0 {
            ((s - leg_start) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        out.push(corners[leg].lerp(corners[leg + 1], f));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn area() -> Rect {
        Rect {
            min: Vec2::new(300.0, 300.0),
            max: Vec2::new(1300.0, 1300.0),
        }
    }

    #[test]
    fn random_paths_respect_the_speed_limit_and_area() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let paths = generate(&PathSpec::default(), 5, 2000, area(), &mut rng);
        assert_eq!(paths.len(), 5);
        for p in &paths {
            assert_eq!(p.positions.len(), 2000);
            assert!(p.positions.iter().all(|q| area().contains(*q)));
            for w in p.positions.windows(2) {
                assert!(w[0].distance(w[1]) <= 0.15 + 1e-9);
            }
            assert!(p.mean_speed() > 0.04);
        }
    }

    #[test]
    fn zigzags_have_the_shape_of_fig_15() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for periods in [1, 3] {
            let spec = PathSpec::Zigzag {
                periods,
                length: 300.0,
                width: 100.0,
            };
            spec.validate(area()).unwrap();
            let p = &generate(&spec, 1, 3001, area(), &mut rng)[0];
            let a = p.positions[0];
            let b = *p.positions.last().unwrap();
            assert!((a.distance(b) - 300.0).abs() < 1e-6);
            let expected =
                4.0 * periods as f64 * (50f64.powi(2) + (75.0 / periods as f64).powi(2)).sqrt();
            assert!(
                (p.length() - expected).abs() < 1e-6,
                "{} vs {expected}",
                p.length()
            );
            // Constant speed along the path.
            let d0 = p.positions[0].distance(p.positions[1]);
            assert!((d0 - expected / 3000.0).abs() < 1e-9);
            assert!(p.positions.iter().all(|q| area().contains(*q)));
        }
        assert!(PathSpec::Zigzag {
            periods: 0,
            length: 300.0,
            width: 100.0
        }
        .validate(area())
        .is_err());
    }
}
