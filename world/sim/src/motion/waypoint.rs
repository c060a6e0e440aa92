//! The random-waypoint model (Johnson & Maltz 1996; Broch et al. 1998) with
//! pauses: every target picks a destination uniformly in the field and a
//! speed uniformly in a range, walks there in a straight line, pauses for a
//! random time, and repeats. Targets ignore one another, so they pass
//! through each other: mixing comes from chance encounters only. A baseline
//! against the interacting crowd of [`super::crowd`].

use super::Motion;
use crate::geometry::{Rect, Vec2};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Parameters of the random-waypoint model.
#[derive(Debug, Clone, PartialEq)]
pub struct WaypointParams {
    /// Walking speed range, m/s, drawn uniformly per leg (default 0.5–1.8).
    pub speed: (f64, f64),
    /// Pause at each waypoint, drawn uniformly, seconds (default 0–5).
    pub pause: (f64, f64),
}

impl Default for WaypointParams {
    fn default() -> Self {
        WaypointParams {
            speed: (0.5, 1.8),
            pause: (0.0, 5.0),
        }
    }
}

impl WaypointParams {
    /// Checks that every parameter is usable; returns what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let (lo, hi) = self.speed;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= lo) {
            return Err(format!(
                "waypoint speed range {:?} must be finite with 0 < min <= max",
                self.speed
            ));
        }
        let (lo, hi) = self.pause;
        if !(lo.is_finite() && hi.is_finite() && lo >= 0.0 && hi >= lo) {
            return Err(format!(
                "waypoint pause range {:?} must be finite with 0 <= min <= max",
                self.pause
            ));
        }
        Ok(())
    }
}

#[derive(Debug, Clone)]
struct Walker {
    pos: Vec2,
    target: Vec2,
    speed: f64,
    pause_left: f64,
}

/// A running random-waypoint model.
#[derive(Debug, Clone)]
pub struct Waypoint {
    params: WaypointParams,
    dt: f64,
    field: Rect,
    rng: ChaCha8Rng,
    walkers: Vec<Walker>,
    positions: Vec<Option<Vec2>>,
    step: u64,
}

impl Waypoint {
    /// `n` targets at uniform positions, each walking to a first waypoint,
    /// moving in steps of `dt` seconds. Panics on invalid parameters, a
    /// non-positive `dt` or an empty field (the scenario builder checks all
    /// three first).
    pub fn new(
        n: usize,
        field: Rect,
        dt: f64,
        params: WaypointParams,
        mut rng: ChaCha8Rng,
    ) -> Self {
        if let Err(e) = params.validate() {
            panic!("{e}");
        }
        assert!(
            dt.is_finite() && dt > 0.0,
            "waypoint dt must be > 0, got {dt}"
        );
        assert!(field.is_valid(), "waypoint field {field:?} is empty");
        let walkers: Vec<Walker> = (0..n)
            .map(|_| {
                let pos = field.sample(&mut rng);
                let target = field.sample(&mut rng);
                let speed = draw(&mut rng, params.speed);
                Walker {
                    pos,
                    target,
                    speed,
                    pause_left: 0.0,
                }
            })
            .collect();
        let positions = walkers.iter().map(|w| Some(w.pos)).collect();
        Waypoint {
            params,
            dt,
            field,
            rng,
            walkers,
            positions,
            step: 0,
        }
    }

    /// Runs the model for `seconds` (so that the start, where nobody is
    /// paused, settles), then counts steps from 0 again.
    pub(crate) fn warm_up(&mut self, seconds: f64) {
        let steps = (seconds / self.dt).round().max(0.0) as u64;
        for _ in 0..steps {
            self.advance();
        }
        self.step = 0;
    }

    pub fn field(&self) -> Rect {
        self.field
    }
}

fn draw(rng: &mut ChaCha8Rng, (lo, hi): (f64, f64)) -> f64 {
    lo + (hi - lo) * rng.gen::<f64>()
}

impl Motion for Waypoint {
    fn targets(&self) -> usize {
        self.walkers.len()
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn step_index(&self) -> u64 {
        self.step
    }

    fn positions(&self) -> &[Option<Vec2>] {
        &self.positions
    }

    fn advance(&mut self) -> bool {
        let dt = self.dt;
        for (i, w) in self.walkers.iter_mut().enumerate() {
            let mut left = dt;
            // A step may finish a leg and start the pause (or even end a
            // short pause and start the next leg): spend the whole step.
            while left > 1e-12 {
                if w.pause_left > 0.0 {
                    let spent = w.pause_left.min(left);
                    w.pause_left -= spent;
                    left -= spent;
                    if w.pause_left <= 0.0 {
                        w.pause_left = 0.0;
                        w.target = self.field.sample(&mut self.rng);
                        w.speed = draw(&mut self.rng, self.params.speed);
                    }
                    continue;
                }
                let to_go = w.target - w.pos;
                let dist = to_go.norm();
                let reach = w.speed * left;
                if reach < dist {
                    w.pos += to_go * (reach / dist);
                    left = 0.0;
                } else {
                    w.pos = w.target;
                    left -= dist / w.speed;
                    w.pause_left = draw(&mut self.rng, self.params.pause);
                    if w.pause_left <= 0.0 {
                        w.target = self.field.sample(&mut self.rng);
                        w.speed = draw(&mut self.rng, self.params.speed);
                    }
                }
            }
            self.positions[i] = Some(w.pos);
        }
        self.step += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn walks_at_bounded_speed_inside_the_field_and_pauses() {
        let field = Rect::with_size(30.0, 30.0);
        let params = WaypointParams::default();
        let mut m = Waypoint::new(25, field, 0.1, params.clone(), ChaCha8Rng::seed_from_u64(8));
        let mut prev: Vec<Vec2> = m.positions().iter().map(|p| p.unwrap()).collect();
        let mut still = 0usize;
        let mut total = 0usize;
        for _ in 0..2000 {
            m.advance();
            for (i, p) in m.positions().iter().enumerate() {
                let p = p.unwrap();
                assert!(field.contains(p));
                let v = p.distance(prev[i]) / 0.1;
                assert!(v <= params.speed.1 + 1e-9, "speed {v}");
                if v == 0.0 {
                    still += 1;
                }
                total += 1;
                prev[i] = p;
            }
        }
        // Legs average ~16 m at ~1.15 m/s (~14 s), pauses 2.5 s.
        let share = still as f64 / total as f64;
        assert!((0.05..0.35).contains(&share), "paused share {share}");
    }

    #[test]
    fn same_seed_same_motion() {
        let field = Rect::with_size(10.0, 10.0);
        let run = |seed| {
            let mut m = Waypoint::new(
                5,
                field,
                0.1,
                WaypointParams::default(),
                ChaCha8Rng::seed_from_u64(seed),
            );
            for _ in 0..50 {
                m.advance();
            }
            m.positions().to_vec()
        };
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }
}
