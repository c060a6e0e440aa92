//! Replay of real, human-annotated pedestrian trajectories (the ETH and UCY
//! scenes of `shared/data/pedestrians`), so that events can be extracted
//! from real crowds exactly as the paper's Section 6 extracts them from its
//! simulated market.
//!
//! - [`format`](mod@format) — the obsmat (8-column) and four-column file
//!   formats (`idmesh-extract`'s parser, which reads them for extraction
//!   too).
//! - [`scene`] — a loaded scene: timing, people, interpolated positions.
//! - [`window`] — which people become tracks, and for how long (each person
//!   is one track for the whole run; see there).
//! - [`Replay`] — the [`Motion`] that samples the chosen people every `dt`.
//!
//! Malformed files are rejected with a [`SceneError`] that reads
//! `FILE:LINE: reason`.

pub(crate) mod error;
pub use idmesh_extract::adapters::eth_ucy as format;
pub(crate) mod scene;
pub(crate) mod window;

pub use error::SceneError;
pub use scene::{Scene, Timing};
pub use window::Window;
pub(crate) use window::WindowSpec;

use super::Motion;
use crate::geometry::Vec2;
use std::sync::Arc;

/// Replays the people of a [`Window`] of a [`Scene`]: target `t` is
/// `window.people[t]`, sampled every `dt` seconds from the window start
/// (linear interpolation between annotations; `None` while absent).
#[derive(Debug, Clone)]
pub(crate) struct Replay {
    scene: Arc<Scene>,
    window: Window,
    dt: f64,
    step: u64,
    max_steps: u64,
    cursors: Vec<usize>,
    positions: Vec<Option<Vec2>>,
}

impl Replay {
    /// Panics if `dt` is not finite and positive (the builder checks it).
    pub(crate) fn new(scene: Arc<Scene>, window: Window, dt: f64) -> Self {
        assert!(
            dt.is_finite() && dt > 0.0,
            "replay dt must be > 0, got {dt}"
        );
        let max_steps = ((window.end - window.start) / dt + 1e-9).floor().max(0.0) as u64;
        let n = window.people.len();
        let mut replay = Replay {
            scene,
            window,
            dt,
            step: 0,
            max_steps,
            cursors: vec![0; n],
            positions: vec![None; n],
        };
        replay.sample();
        replay
    }

    fn sample(&mut self) {
        let time = self.window.start + self.step as f64 * self.dt;
        for (t, &person) in self.window.people.iter().enumerate() {
            self.positions[t] = self.scene.position_at(person, time, &mut self.cursors[t]);
        }
    }
}

impl Motion for Replay {
    fn targets(&self) -> usize {
        self.window.people.len()
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

    fn max_steps(&self) -> Option<u64> {
        Some(self.max_steps)
    }

    fn advance(&mut self) -> bool {
        if self.step >= self.max_steps {
            return false;
        }
        self.step += 1;
        self.sample();
        true
    }
}

/// Where the shipped scenes live: `$IDMESH_PEDESTRIANS` if set, else
/// `../shared/data/pedestrians` if there is one, else
/// `/work/shared/data/pedestrians`.
pub fn data_dir() -> std::path::PathBuf {
    if let Some(dir) = std::env::var_os("IDMESH_PEDESTRIANS") {
        return dir.into();
    }
    // `shared/` lives beside the repository: found from the repository's
    // root (where the README's commands run), else where this project's
    // machines keep it.
    let beside = std::path::PathBuf::from("../shared/data/pedestrians");
    if beside.is_dir() {
        beside
    } else {
        "/work/shared/data/pedestrians".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use format::SceneFormat;

    #[test]
    fn loads_the_real_eth_obsmat_scene() {
        let path = data_dir().join("eth/obsmat/obsmat.txt");
        let scene = Scene::load(&path, Timing::Auto).unwrap();
        assert_eq!(scene.format, SceneFormat::Obsmat);
        assert_eq!(scene.rows(), 8908);
        assert_eq!(scene.people.len(), 360);
        // Native frames 780–12381 at step 6 = 0.4 s.
        assert!((scene.annotation_step - 0.4).abs() < 1e-12);
        assert!((scene.duration() - (12381.0 - 780.0) * 0.4 / 6.0).abs() < 1e-6);
        // The README's median walking speed (1.47 m/s) at these timings.
        let mut speeds = Vec::new();
        for p in &scene.people {
            for w in p.samples.windows(2) {
                speeds.push(w[0].pos.distance(w[1].pos) / (w[1].time - w[0].time));
            }
        }
        speeds.sort_by(f64::total_cmp);
        let median = speeds[speeds.len() / 2];
        assert!((1.3..1.6).contains(&median), "median speed {median}");
    }

    #[test]
    fn loads_the_four_column_scenes() {
        for (file, people, rows, max_at_once) in [
            ("univ/students001.txt", 415, 21813, 75),
            ("zara01/crowds_zara01.txt", 148, 5153, 20),
            ("eth/biwi_eth.txt", 360, 5492, 27),
        ] {
            let scene = Scene::load(data_dir().join(file), Timing::Auto).unwrap();
            assert_eq!(scene.format, SceneFormat::FourColumn, "{file}");
            assert_eq!(scene.people.len(), people, "{file}");
            assert_eq!(scene.rows(), rows, "{file}");
            // Replaying at the annotation rate sees the README's peak crowd.
            let step = scene.annotation_step;
            let window = Window::choose(&scene, &WindowSpec::default()).unwrap();
            let mut replay = Replay::new(Arc::new(scene), window, step);
            let mut peak = 0;
            loop {
                peak = peak.max(replay.positions().iter().flatten().count());
                if !replay.advance() {
                    break;
                }
            }
            assert_eq!(peak, max_at_once, "{file}");
        }
    }

    #[test]
    fn a_malformed_file_is_rejected_with_file_and_line() {
        let path = std::env::temp_dir().join(format!(
            "idmesh-sensor-malformed-{}.txt",
            std::process::id()
        ));
        let real = std::fs::read_to_string(data_dir().join("hotel/obsmat/obsmat.txt")).unwrap();
        let mut lines: Vec<&str> = real.lines().take(40).collect();
        lines[36] = "   1.0e+01   2.0e+00   oops   0.0   1.0   0.0   0.0   0.0";
        std::fs::write(&path, lines.join("\n")).unwrap();
        let err = Scene::load(&path, Timing::Auto).unwrap_err();
        std::fs::remove_file(&path).ok();
        assert_eq!(
            err.to_string(),
            format!(
                "{}:37: column 3 (pos_x): `oops` is not a finite number",
                path.display()
            )
        );
        let missing = Scene::load("/nonexistent/idmesh/scene.txt", Timing::Auto).unwrap_err();
        assert!(missing
            .to_string()
            .starts_with("/nonexistent/idmesh/scene.txt: "));
    }

    #[test]
    fn replay_follows_the_window() {
        let text = "0 1 0 0\n10 1 1 0\n20 1 2 0\n10 2 5 5\n20 2 5 6\n";
        let scene = Arc::new(Scene::parse(text, "r.txt", Timing::Auto).unwrap());
        let window = Window::choose(&scene, &WindowSpec::default()).unwrap();
        let mut r = Replay::new(scene, window, 0.1);
        assert_eq!(r.max_steps(), Some(8));
        assert_eq!(r.positions(), &[Some(Vec2::new(0.0, 0.0)), None]);
        for _ in 0..6 {
            assert!(r.advance());
        }
        // 0.6 s: person 1 between x=1 (0.4 s) and x=2 (0.8 s).
        let p = r.positions()[0].unwrap();
        assert!((p.x - 1.5).abs() < 1e-9);
        assert!(r.positions()[1].is_some());
        assert!(r.advance() && r.advance());
        assert!(!r.advance());
        assert_eq!(r.step_index(), 8);
    }
}
