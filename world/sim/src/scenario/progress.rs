//! Progress reporting, so a command line can draw a progress bar.
//!
//! A generation run calls the hook as `progress(done, total)` with
//! `done ≤ total`, never decreasing, about every 0.1 % of the work and
//! once more at the end. For a run of fixed duration the unit is
//! simulation steps; for a run of a fixed number of events it is events.

/// The progress hook: `(done, total)`.
pub(crate) type Progress<'a> = &'a mut dyn FnMut(u64, u64);

/// Calls a hook only when at least 1/1000 of the work has been done since
/// the last call (and always for the final value), keeping the cost of a
/// redraw-heavy hook negligible.
pub(crate) struct Throttle<'a> {
    hook: Progress<'a>,
    total: u64,
    stride: u64,
    last: Option<u64>,
}

impl<'a> Throttle<'a> {
    pub(crate) fn new(hook: Progress<'a>, total: u64) -> Self {
        Throttle {
            hook,
            total,
            stride: (total / 1000).max(1),
            last: None,
        }
    }

    pub(crate) fn report(&mut self, done: u64) {
        let done = done.min(self.total);
        let due = match self.last {
            None => true,
            Some(last) => done >= last + self.stride || (done == self.total && last != done),
        };
        if due {
            (self.hook)(done, self.total);
            self.last = Some(done);
        }
    }

    /// Reports completion (`total, total`) if it was not reported yet.
    pub(crate) fn finish(&mut self) {
        self.report(self.total);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn throttles_and_finishes() {
        let mut calls = Vec::new();
        {
            let mut hook = |d: u64, t: u64| calls.push((d, t));
            let mut th = Throttle::new(&mut hook, 10_000);
            for d in 0..=9_999 {
                th.report(d);
            }
            th.finish();
            th.finish();
        }
        assert_eq!(calls.first(), Some(&(0, 10_000)));
        assert_eq!(calls.last(), Some(&(10_000, 10_000)));
        assert!(calls.len() <= 1002, "{}", calls.len());
        assert!(calls.windows(2).all(|w| w[0].0 < w[1].0));
    }
}
