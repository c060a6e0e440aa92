//! What `idmesh up` does when one of its processes exits: the pure machine
//! of its supervision (the driver is `launch::up`, which spawns, polls and
//! signals). A process that fails — a non-zero exit, or a signal such as
//! kill -9 — is started again after a backoff that doubles with each
//! failure in a row (0.5 s, 1 s, 2 s, … at most 30 s) and starts over once
//! it has run a minute; its neighbours on the host are left alone. A
//! process that ends of itself (exit 0: a role told to stop) stays
//! down. The loss of a whole host is
//! not this machine's: that is what standbys on other hosts are for.

use std::time::{Duration, Instant};

/// The wait before the first restart of a failed process.
pub const FIRST_BACKOFF: Duration = Duration::from_millis(500);
/// The longest wait between restarts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(30);
/// A process that ran this long before failing starts its backoff over.
pub const STABLE: Duration = Duration::from_secs(60);

#[derive(Debug, Clone, PartialEq)]
enum State {
    Running {
        since: Instant,
    },
    /// Failed; started again at `at`.
    Waiting {
        at: Instant,
    },
    /// Ended of itself.
    Done,
}

#[derive(Debug, Clone)]
struct Watched {
    name: String,
    state: State,
    /// Failures in a row (reset by a stable run).
    failures: u32,
}

/// What became of an exited process.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Started again after this wait (the failures in a row so far).
    Restart { after: Duration, failures: u32 },
    /// It ended of itself and stays down.
    Ended,
}

/// The supervision of one host's processes, by name.
#[derive(Debug, Clone)]
pub struct Supervisor {
    watched: Vec<Watched>,
}

impl Supervisor {
    /// Supervises `names`, all running since `now`.
    pub fn new<'a>(names: impl IntoIterator<Item = &'a str>, now: Instant) -> Self {
        Supervisor {
            watched: names
                .into_iter()
                .map(|name| Watched {
                    name: name.to_string(),
                    state: State::Running { since: now },
                    failures: 0,
                })
                .collect(),
        }
    }

    /// Process `name` exited at `now`, successfully or not.
    pub fn exited(&mut self, name: &str, success: bool, now: Instant) -> Option<Verdict> {
        let w = self.watched.iter_mut().find(|w| w.name == name)?;
        let State::Running { since } = w.state else {
            return None;
        };
        if success {
            w.state = State::Done;
            return Some(Verdict::Ended);
        }
        if now.duration_since(since) >= STABLE {
            w.failures = 0;
        }
        w.failures += 1;
        let after = backoff(w.failures);
        w.state = State::Waiting { at: now + after };
        Some(Verdict::Restart {
            after,
            failures: w.failures,
        })
    }

    /// The processes whose restart is due at `now` (each is taken as
    /// started: call [`Supervisor::exited`] if it fails again).
    pub fn due(&mut self, now: Instant) -> Vec<String> {
        let mut out = Vec::new();
        for w in &mut self.watched {
            if matches!(w.state, State::Waiting { at } if at <= now) {
                w.state = State::Running { since: now };
                out.push(w.name.clone());
            }
        }
        out
    }

    /// Every process ended of itself: nothing is left to supervise.
    pub fn all_ended(&self) -> bool {
        self.watched.iter().all(|w| w.state == State::Done)
    }
}

/// The wait before the restart after `failures` failures in a row.
pub fn backoff(failures: u32) -> Duration {
    let doublings = failures.saturating_sub(1).min(16);
    (FIRST_BACKOFF * 2u32.pow(doublings)).min(MAX_BACKOFF)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_process_is_restarted_after_a_doubling_backoff() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(["leader-0", "sensor-0"], t0);
        let mut now = t0 + Duration::from_secs(1);
        let mut waits = Vec::new();
        for _ in 0..8 {
            let Some(Verdict::Restart { after, .. }) = s.exited("leader-0", false, now) else {
                panic!("a failure is restarted");
            };
            waits.push(after.as_millis());
            assert!(s.due(now + after - Duration::from_millis(1)).is_empty());
            now += after;
            assert_eq!(s.due(now), vec!["leader-0".to_string()]);
            now += Duration::from_secs(1);
        }
        assert_eq!(waits, [500, 1000, 2000, 4000, 8000, 16000, 30000, 30000]);
        assert!(!s.all_ended());
    }

    #[test]
    fn a_stable_run_starts_the_backoff_over() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(["leader-0"], t0);
        let now = t0 + Duration::from_secs(1);
        s.exited("leader-0", false, now);
        let now = now + FIRST_BACKOFF;
        assert_eq!(s.due(now).len(), 1);
        let short = s.exited("leader-0", false, now + Duration::from_secs(5));
        assert!(matches!(short, Some(Verdict::Restart { failures: 2, .. })));
        let now = now + Duration::from_secs(5) + backoff(2);
        assert_eq!(s.due(now).len(), 1);
        let long = s.exited("leader-0", false, now + STABLE);
        assert_eq!(
            long,
            Some(Verdict::Restart {
                after: FIRST_BACKOFF,
                failures: 1
            })
        );
    }

    #[test]
    fn a_process_that_ends_of_itself_stays_down_and_its_neighbours_run_on() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(["sensor-0", "leader-0"], t0);
        assert_eq!(s.exited("sensor-0", true, t0), Some(Verdict::Ended));
        assert!(s.due(t0 + MAX_BACKOFF).is_empty());
        assert!(!s.all_ended(), "leader-0 still runs");
        // A second report of an exit it already handled changes nothing.
        assert_eq!(s.exited("sensor-0", false, t0), None);
        assert_eq!(s.exited("leader-0", true, t0), Some(Verdict::Ended));
        assert!(s.all_ended());
        assert_eq!(s.exited("nobody", false, t0), None);
    }
}
