//! A social-force crowd (Helbing & Molnár, Phys. Rev. E 51, 1995; the
//! circular specification of Helbing, Farkas & Vicsek, Nature 407, 2000),
//! standing in for the Delta3D market crowd of the paper's Section 6.
//!
//! Every target walks towards a goal at its own desired speed, is pushed
//! away from the others by an exponential repulsion that is weaker from
//! behind, keeps off the walls of the rectangular field, pauses a moment at
//! each goal ("browsing a stall") and then picks a new one. The result is the
//! dense, interacting motion — people slowing, swerving and passing close —
//! that makes mixing events frequent and observations rarer in the crowd's
//! core.
//!
//! Integration is semi-implicit Euler at a fixed step (default 0.1 s). All
//! randomness (start positions, goals, desired speeds, pauses, a small
//! fluctuation force) comes from the `ChaCha8Rng` passed in, in a fixed order,
//! so a seed fixes the motion.

mod agent;
mod forces;
mod goals;

pub use goals::Goals;

use self::agent::Agent;
use super::Motion;
use crate::geometry::{NeighbourGrid, Rect, Vec2};
use rand_chacha::ChaCha8Rng;

/// The parameters of the crowd; accelerations are in m/s² (forces per unit
/// mass), distances in metres, times in seconds.
#[derive(Debug, Clone, PartialEq)]
pub struct CrowdParams {
    /// Mean and standard deviation of the desired walking speed, m/s
    /// (default 1.34 ± 0.26, Helbing & Molnár); draws are clipped to
    /// [0.5, 2.5].
    pub desired_speed: (f64, f64),
    /// Relaxation time τ of the driving force (v0·e − v)/τ (default 0.5 s).
    pub relaxation: f64,
    /// A target never walks faster than this multiple of its desired speed
    /// (default 1.3).
    pub max_speed_factor: f64,
    /// Body radius (default 0.25 m): two people touch at 0.5 m.
    pub radius: f64,
    /// Strength A of the repulsion A·exp((r_ij − d_ij)/B) between two
    /// people (default 5 m/s²) ...
    pub repulsion: f64,
    /// ... and its range B (default 0.3 m).
    pub repulsion_range: f64,
    /// Weight λ of a repulsion coming from behind (default 0.35; 1 = as
    /// strong as from the front).
    pub anisotropy: f64,
    /// Strength (default 5 m/s²) and range (default 0.2 m) of the walls'
    /// repulsion A_w·exp((r − d_w)/B_w).
    pub wall_repulsion: f64,
    pub wall_range: f64,
    /// People further apart than this do not interact (default 2.5 m).
    pub interaction_cutoff: f64,
    /// Standard deviation of an independent random fluctuation of every
    /// acceleration component, m/s² (default 0.3): breaks symmetric
    /// deadlocks.
    pub fluctuation: f64,
    /// Where goals are drawn (default [`Goals::Uniform`]).
    pub goals: Goals,
    /// A goal within this distance is reached (default 0.5 m).
    pub arrival_radius: f64,
    /// Pause at a reached goal, drawn uniformly from this range
    /// (default 0–4 s).
    pub dwell: (f64, f64),
}

impl Default for CrowdParams {
    fn default() -> Self {
        CrowdParams {
            desired_speed: (1.34, 0.26),
            relaxation: 0.5,
            max_speed_factor: 1.3,
            radius: 0.25,
            repulsion: 5.0,
            repulsion_range: 0.3,
            anisotropy: 0.35,
            wall_repulsion: 5.0,
            wall_range: 0.2,
            interaction_cutoff: 2.5,
            fluctuation: 0.3,
            goals: Goals::Uniform,
            arrival_radius: 0.5,
            dwell: (0.0, 4.0),
        }
    }
}

impl CrowdParams {
    /// Checks that every parameter is usable; returns what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("relaxation", self.relaxation),
            ("max_speed_factor", self.max_speed_factor),
            ("repulsion_range", self.repulsion_range),
            ("wall_range", self.wall_range),
            ("interaction_cutoff", self.interaction_cutoff),
            ("arrival_radius", self.arrival_radius),
            ("desired_speed mean", self.desired_speed.0),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("crowd {name} must be finite and > 0, got {v}"));
            }
        }
        let non_negative = [
            ("radius", self.radius),
            ("repulsion", self.repulsion),
            ("wall_repulsion", self.wall_repulsion),
            ("fluctuation", self.fluctuation),
            ("desired_speed deviation", self.desired_speed.1),
            ("dwell minimum", self.dwell.0),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("crowd {name} must be finite and >= 0, got {v}"));
            }
        }
        if !(self.dwell.1.is_finite() && self.dwell.1 >= self.dwell.0) {
            return Err(format!(
                "crowd dwell range {:?} must be finite with min <= max",
                self.dwell
            ));
        }
        if !(0.0..=1.0).contains(&self.anisotropy) {
            return Err(format!(
                "crowd anisotropy must be in [0, 1], got {}",
                self.anisotropy
            ));
        }
        self.goals.validate()
    }
}

/// A running social-force crowd of `n` targets in a rectangular field.
#[derive(Debug, Clone)]
pub struct Crowd {
    params: CrowdParams,
    dt: f64,
    field: Rect,
    rng: ChaCha8Rng,
    goals: goals::GoalSampler,
    agents: Vec<Agent>,
    positions: Vec<Option<Vec2>>,
    grid: NeighbourGrid,
    accel: Vec<Vec2>,
    step: u64,
}

impl Crowd {
    /// Places `n` targets in `field` (uniformly, avoiding overlaps where the
    /// field leaves room), each with a first goal and a desired speed; the
    /// crowd then moves in steps of `dt` seconds.
    ///
    /// Panics if `params` do not validate, `dt` is not positive or the field
    /// is empty; the scenario builder checks all three first.
    pub(crate) fn new(
        n: usize,
        field: Rect,
        dt: f64,
        params: CrowdParams,
        mut rng: ChaCha8Rng,
    ) -> Self {
        if let Err(e) = params.validate() {
            panic!("{e}");
        }
        assert!(dt.is_finite() && dt > 0.0, "crowd dt must be > 0, got {dt}");
        assert!(field.is_valid(), "crowd field {field:?} is empty");
        let goals = goals::GoalSampler::new(&params.goals, field, &mut rng);
        let inner = field.shrink(params.radius);
        let mut agents: Vec<Agent> = Vec::with_capacity(n);
        let min_gap = 2.0 * params.radius + 0.1;
        for _ in 0..n {
            let mut pos = inner.sample(&mut rng);
            for _ in 0..50 {
                if agents.iter().all(|a| a.pos.distance(pos) >= min_gap) {
                    break;
                }
                pos = inner.sample(&mut rng);
            }
            agents.push(Agent::new(pos, &params, &goals, &mut rng));
        }
        let positions = agents.iter().map(|a| Some(a.pos)).collect();
        Crowd {
            params,
            dt,
            field,
            rng,
            goals,
            agents,
            positions,
            grid: NeighbourGrid::new(),
            accel: vec![Vec2::ZERO; n],
            step: 0,
        }
    }

    /// Runs the crowd for `seconds` (so that the random start settles into
    /// walking), then counts steps from 0 again.
    pub(crate) fn warm_up(&mut self, seconds: f64) {
        let steps = (seconds / self.dt).round().max(0.0) as u64;
        for _ in 0..steps {
            self.advance();
        }
        self.step = 0;
    }

    #[cfg(test)]
    pub fn field(&self) -> Rect {
        self.field
    }
}

impl Motion for Crowd {
    fn targets(&self) -> usize {
        self.agents.len()
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
        let p = &self.params;
        let dt = self.dt;
        self.grid.rebuild(&self.positions, p.interaction_cutoff);
        for i in 0..self.agents.len() {
            let a = &self.agents[i];
            let heading = a.heading();
            let mut acc = forces::driving(a.desired_velocity(), a.vel, p.relaxation);
            self.grid
                .for_each_neighbour(&self.positions, i, p.interaction_cutoff, |j, _| {
                    acc += forces::between_people(a.pos, heading, self.agents[j].pos, p);
                });
            acc += forces::from_walls(a.pos, self.field, p);
            acc += forces::fluctuation(&mut self.rng, p.fluctuation);
            self.accel[i] = acc;
        }
        for (i, a) in self.agents.iter_mut().enumerate() {
            a.vel = (a.vel + self.accel[i] * dt).clamp_norm(a.desired_speed * p.max_speed_factor);
            let next = a.pos + a.vel * dt;
            let kept = self.field.clamp(next);
            if kept.x != next.x {
                a.vel.x = 0.0;
            }
            if kept.y != next.y {
                a.vel.y = 0.0;
            }
            a.pos = kept;
            a.update_goal(dt, p, &self.goals, &mut self.rng);
            self.positions[i] = Some(a.pos);
        }
        self.step += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn crowd(seed: u64, n: usize) -> Crowd {
        Crowd::new(
            n,
            Rect::with_size(20.0, 15.0),
            0.1,
            CrowdParams::default(),
            ChaCha8Rng::seed_from_u64(seed),
        )
    }

    #[test]
    fn stays_in_the_field_at_walking_speeds() {
        let mut c = crowd(1, 40);
        let field = c.field();
        let mut prev: Vec<Vec2> = c.positions().iter().map(|p| p.unwrap()).collect();
        let mut speeds = Vec::new();
        for _ in 0..600 {
            assert!(c.advance());
            for (i, p) in c.positions().iter().enumerate() {
                let p = p.unwrap();
                assert!(field.contains(p), "{p:?} left the field");
                let v = p.distance(prev[i]) / c.dt();
                assert!(v <= 2.5 * 1.3 + 1e-9, "speed {v}");
                speeds.push(v);
                prev[i] = p;
            }
        }
        speeds.sort_by(f64::total_cmp);
        let median = speeds[speeds.len() / 2];
        assert!((0.6..1.8).contains(&median), "median speed {median}");
        assert_eq!(c.step_index(), 600);
        assert!((c.time() - 60.0).abs() < 1e-9);
    }

    #[test]
    fn people_keep_some_distance() {
        let mut c = crowd(2, 60);
        let mut close = 0usize;
        let mut pairs = 0usize;
        for _ in 0..300 {
            c.advance();
            let pos: Vec<Vec2> = c.positions().iter().map(|p| p.unwrap()).collect();
            for i in 0..pos.len() {
                for j in i + 1..pos.len() {
                    pairs += 1;
                    if pos[i].distance(pos[j]) < 0.3 {
                        close += 1;
                    }
                }
            }
        }
        // Without repulsion ~0.1 % of pairs would overlap this much.
        assert!((close as f64) < 1e-4 * pairs as f64, "{close} of {pairs}");
    }

    #[test]
    fn same_seed_same_motion() {
        let mut a = crowd(9, 30);
        let mut b = crowd(9, 30);
        let mut c = crowd(10, 30);
        for _ in 0..100 {
            a.advance();
            b.advance();
            c.advance();
        }
        assert_eq!(a.positions(), b.positions());
        assert_ne!(a.positions(), c.positions());
    }
}
