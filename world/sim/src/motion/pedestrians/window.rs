//! Which people of a scene become the targets of a run, and for how long.
//!
//! The property filters work on a fixed set of n tracks, but in a real
//! scene people come and go. The mapping used here: **each person is one
//! track for the whole run**, numbered in order of arrival (ties by file
//! id). A track exists before its person arrives and after they leave, but
//! events only ever involve people present at that moment — a track is
//! silent while its person is away. Ground truth (which tracks are red)
//! covers every track all the time.
//!
//! The run covers the scene from `start` on. With a cap of n people, the run
//! is cut just before the (n+1)-th person arrives, so that **everyone
//! present during the run is one of the n targets**: no untracked person
//! ever walks among the tracked ones (who would otherwise be invisible to the
//! mixing and isolation tests). A cap smaller than the number of people
//! already present at `start` is therefore an error. A `max_duration`
//! shortens the run further; without either, it lasts to the end of the
//! scene.

use super::error::SceneError;
use super::scene::{Scene, TIME_EPS};

/// What part of a scene to replay.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct WindowSpec {
    /// Seconds from the scene's first annotation (default 0).
    pub start: f64,
    /// At most this many people (default: everyone in the window).
    pub max_people: Option<usize>,
    /// At most this many seconds (default: to the end of the scene, or of
    /// the cap on people).
    pub max_duration: Option<f64>,
}

/// The chosen part of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// Scene time of run time 0, seconds.
    pub start: f64,
    /// Last scene time of the run (inclusive), seconds.
    pub end: f64,
    /// Indices into `scene.people`, in track order: `people[t]` is on
    /// track t at the start.
    pub people: Vec<usize>,
}

impl Window {
    /// Chooses the people and the time span of a run.
    pub(crate) fn choose(scene: &Scene, spec: &WindowSpec) -> Result<Window, SceneError> {
        let fail = |reason: String| SceneError::Window {
            file: scene.source.clone(),
            reason,
        };
        let scene_end = scene.duration();
        if !(spec.start.is_finite() && spec.start >= 0.0 && spec.start < scene_end) {
            return Err(fail(format!(
                "window start {} s is outside the scene (0 to {scene_end:.1} s)",
                spec.start
            )));
        }
        let mut end = scene_end;
        if let Some(d) = spec.max_duration {
            if d.is_nan() || d <= 0.0 {
                return Err(fail(format!("window duration must be > 0, got {d}")));
            }
            end = end.min(spec.start + d);
        }
        // Everyone who is still to be seen at `start`, by arrival.
        let mut arrivals: Vec<(f64, usize)> = scene
            .people
            .iter()
            .enumerate()
            .filter(|(_, p)| p.last_time() >= spec.start - TIME_EPS)
            .map(|(i, p)| (p.first_time().max(spec.start), i))
            .filter(|&(arrival, _)| arrival <= end + TIME_EPS)
            .collect();
        arrivals.sort_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(scene.people[a.1].id.cmp(&scene.people[b.1].id))
        });
        if let Some(cap) = spec.max_people {
            if arrivals.len() > cap {
                let cut = arrivals[cap].0;
                let present_at_start = arrivals
                    .iter()
                    .filter(|a| a.0 <= spec.start + TIME_EPS)
                    .count();
                if cut <= spec.start + TIME_EPS {
                    return Err(fail(format!(
                        "{present_at_start} people are present at {} s, more than the {cap} asked for: \
                         ask for at least {present_at_start}, or for everyone",
                        spec.start
                    )));
                }
                // Just before the (cap+1)-th arrival; everyone who arrives at
                // that same moment is left out with them.
                end = end.min(cut - 10.0 * TIME_EPS);
                arrivals.retain(|a| a.0 < cut - TIME_EPS);
            }
        }
        if arrivals.is_empty() {
            return Err(fail(format!(
                "nobody is in the scene from {} s",
                spec.start
            )));
        }
        Ok(Window {
            start: spec.start,
            end,
            people: arrivals.into_iter().map(|(_, i)| i).collect(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::pedestrians::Timing;

    // Person 1: 0–0.8 s, person 2: 0–0.4 s, person 3: 0.8–1.2 s, person 4: 1.2 s.
    const TEXT: &str = "\
0 1 0 0
0 2 1 0
10 1 0 1
10 2 1 1
20 1 0 2
20 3 5 5
30 3 5 6
30 4 9 9
";

    fn scene() -> Scene {
        Scene::parse(TEXT, "w.txt", Timing::Auto).unwrap()
    }

    #[test]
    fn everyone_by_default_in_arrival_order() {
        let s = scene();
        let w = Window::choose(&s, &WindowSpec::default()).unwrap();
        let ids: Vec<u32> = w.people.iter().map(|&i| s.people[i].id).collect();
        assert_eq!(ids, [1, 2, 3, 4]);
        assert!((w.end - 1.2).abs() < 1e-12);
    }

    #[test]
    fn a_cap_cuts_the_run_before_the_next_arrival() {
        let s = scene();
        let spec = WindowSpec {
            max_people: Some(2),
            ..Default::default()
        };
        let w = Window::choose(&s, &spec).unwrap();
        assert_eq!(w.people.len(), 2);
        assert!(w.end < 0.8 && w.end > 0.79, "{}", w.end);
        let too_few = WindowSpec {
            max_people: Some(1),
            ..Default::default()
        };
        let err = Window::choose(&s, &too_few).unwrap_err().to_string();
        assert!(
            err.starts_with("w.txt: 2 people are present at 0 s"),
            "{err}"
        );
    }

    #[test]
    fn a_late_start_skips_people_who_left() {
        let s = scene();
        let spec = WindowSpec {
            start: 0.6,
            max_duration: Some(0.3),
            ..Default::default()
        };
        let w = Window::choose(&s, &spec).unwrap();
        let ids: Vec<u32> = w.people.iter().map(|&i| s.people[i].id).collect();
        assert_eq!(ids, [1, 3]);
        assert!((w.end - 0.9).abs() < 1e-12);
        assert!(Window::choose(
            &s,
            &WindowSpec {
                start: 5.0,
                ..Default::default()
            }
        )
        .is_err());
    }
}
