//! The simulated sensor: fed the positions of every step, it emits the
//! `mix` and `observe` events of that step (Section 6 of the paper) and
//! keeps the ground truth — which tracks carry red targets — in step with
//! the swaps it draws. Which pairs meet and which targets are isolated is
//! `idmesh-extract`'s [`FrameSensing`], exactly as for a real tracker's
//! reports; what is simulated is only what a real tracker would decide
//! (the swaps) and what a real sensor would see (the outcomes).
//!
//! Within a step, mixes come first (pairs in ascending target order, each
//! exchanging its two targets' tracks with probability `swap`), then
//! observations (isolated targets in ascending order, on the track each
//! follows after this step's mixes).

use super::assignment::Assignment;
use super::event::{SimEvent, TimedEvent};
use super::sensor_model::SensorModel;
use crate::geometry::Vec2;
use idmesh_extract::frame::FrameSensing;
use idmesh_extract::meetings::Entering;
use idmesh_extract::ExtractorConfig;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// How events are extracted from motion.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtractionParams {
    /// Two targets closer than this mix (metres).
    pub mix_distance: f64,
    /// A mixed pair can mix again only after separating beyond
    /// `release_factor × mix_distance` (≥ 1).
    pub release_factor: f64,
    /// A target with nobody within this distance is isolated and can be
    /// observed (metres).
    pub observe_distance: f64,
    /// At most one observation per target per this many seconds.
    pub observe_interval: f64,
    /// Probability that the tracker exchanges two mixing targets.
    pub swap: f64,
    /// What an observation reports.
    pub sensor: SensorModel,
}

impl Default for ExtractionParams {
    /// The scenario defaults: mix within 1 m (release at 1.25 m), observe
    /// beyond 3.5 m at most every 3 s, swap 0.5, colour-histogram sensor.
    fn default() -> Self {
        ExtractionParams {
            mix_distance: 1.0,
            release_factor: 1.25,
            observe_distance: 3.5,
            observe_interval: 3.0,
            swap: 0.5,
            sensor: SensorModel::colour_histogram(),
        }
    }
}

impl ExtractionParams {
    /// Checks that every parameter is usable; returns what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        // The distances and the interval are the extractor's settings:
        // checked by it, with its words.
        ExtractorConfig {
            mix_distance: self.mix_distance,
            release_factor: self.release_factor,
            observe_distance: self.observe_distance,
            observe_interval: self.observe_interval,
            ..ExtractorConfig::default()
        }
        .validate()
        .map_err(|e| e.to_string())?;
        if !(0.0..=1.0).contains(&self.swap) {
            return Err(format!(
                "swap probability must be in [0, 1], got {}",
                self.swap
            ));
        }
        Ok(())
    }
}

/// Turns successive frames of positions into events.
#[derive(Debug, Clone)]
pub struct Extractor {
    params: ExtractionParams,
    is_red: Vec<bool>,
    assignment: Assignment,
    sensing: FrameSensing,
    swap_rng: ChaCha8Rng,
    sensor_rng: ChaCha8Rng,
    entering: Vec<Entering>,
    due: Vec<u32>,
}

impl Extractor {
    /// `is_red[i]` is the colour of target i; track t starts on target t.
    /// Swap draws come from `swap_rng`, sensor draws from `sensor_rng`.
    /// Panics on invalid parameters (the scenario builder checks them).
    pub fn new(
        params: ExtractionParams,
        is_red: Vec<bool>,
        swap_rng: ChaCha8Rng,
        sensor_rng: ChaCha8Rng,
    ) -> Self {
        if let Err(e) = params.validate() {
            panic!("{e}");
        }
        let n = is_red.len();
        Extractor {
            sensing: FrameSensing::new(
                n,
                params.mix_distance,
                params.mix_distance * params.release_factor,
                params.observe_distance,
                params.observe_interval,
            ),
            params,
            is_red,
            assignment: Assignment::identity(n),
            swap_rng,
            sensor_rng,
            entering: Vec::new(),
            due: Vec::new(),
        }
    }

    /// Extracts the events of the step at `time` from `positions`, appending
    /// at most `limit` of them to `out`; returns how many it appended. When
    /// the limit cuts a step short, the rest of that step is dropped
    /// (including its swaps), so the truth matches the events kept.
    pub fn step(
        &mut self,
        time: f64,
        positions: &[Option<Vec2>],
        out: &mut Vec<TimedEvent>,
        limit: usize,
    ) -> usize {
        debug_assert_eq!(positions.len(), self.is_red.len());
        self.entering.clear();
        self.due.clear();
        // Every target is eligible: the simulated sensor looks at any
        // isolated target (and may see nothing, an outcome that reports
        // nothing). No draw happens here, so the draws below come in the
        // order they always did.
        self.sensing
            .sense(time, positions, |_| true, &mut self.entering, &mut self.due);
        let mut added = 0;
        for e in &self.entering {
            if added == limit {
                return added;
            }
            let (i, j) = (e.a as usize, e.b as usize);
            let (a, b) = (self.assignment.track_of(i), self.assignment.track_of(j));
            let exchanged = self.swap_rng.gen::<f64>() < self.params.swap;
            if exchanged {
                self.assignment.exchange_targets(i, j);
            }
            out.push(TimedEvent {
                time,
                event: SimEvent::Mix {
                    a,
                    b,
                    swap: self.params.swap,
                    exchanged,
                },
            });
            added += 1;
        }
        for &i in &self.due {
            if added == limit {
                return added;
            }
            let i = i as usize;
            if let Some((red, blue)) = self
                .params
                .sensor
                .observe(&mut self.sensor_rng, self.is_red[i])
            {
                out.push(TimedEvent {
                    time,
                    event: SimEvent::Observe {
                        track: self.assignment.track_of(i),
                        red,
                        blue,
                    },
                });
                added += 1;
            }
        }
        added
    }

    pub fn params(&self) -> &ExtractionParams {
        &self.params
    }

    /// Which target is on which track now.
    pub fn assignment(&self) -> &Assignment {
        &self.assignment
    }

    /// The colours of the targets.
    pub fn target_is_red(&self) -> &[bool] {
        &self.is_red
    }

    /// The tracks carrying red targets now, ascending.
    pub fn red_tracks(&self) -> Vec<u32> {
        self.assignment.red_tracks(&self.is_red)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_certain_swap_moves_the_colour_to_the_other_track() {
        let params = ExtractionParams {
            swap: 1.0,
            ..Default::default()
        };
        let rng = || ChaCha8Rng::seed_from_u64(1);
        let mut x = Extractor::new(params, vec![true, false, false], rng(), rng());
        let mut out = Vec::new();
        let far = [
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(10.0, 0.0)),
            Some(Vec2::new(20.0, 0.0)),
        ];
        x.step(0.0, &far, &mut out, usize::MAX);
        assert!(out
            .iter()
            .all(|e| matches!(e.event, SimEvent::Observe { .. })));
        out.clear();
        let close = [
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(0.5, 0.0)),
            Some(Vec2::new(20.0, 0.0)),
        ];
        x.step(0.1, &close, &mut out, usize::MAX);
        assert_eq!(
            out[0].event,
            SimEvent::Mix {
                a: 0,
                b: 1,
                swap: 1.0,
                exchanged: true
            }
        );
        assert_eq!(x.red_tracks(), vec![1]);
        assert_eq!(x.assignment().target_on(1), 0);
    }

    #[test]
    fn a_limit_cuts_the_step() {
        let params = ExtractionParams {
            swap: 1.0,
            ..Default::default()
        };
        let rng = || ChaCha8Rng::seed_from_u64(1);
        let mut x = Extractor::new(params, vec![true, false, false, false], rng(), rng());
        let positions = [
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(0.5, 0.0)),
            Some(Vec2::new(10.0, 0.0)),
            Some(Vec2::new(10.5, 0.0)),
        ];
        let mut out = Vec::new();
        assert_eq!(x.step(0.0, &positions, &mut out, 1), 1);
        assert_eq!(out.len(), 1);
        assert_eq!(x.red_tracks(), vec![1]);
    }
}
