//! A tracker's track ids as the belief's track numbers. A ROS message
//! names a track by a string (a detection's `id`, an object's UUID); the
//! belief's tracks are `0..n`. An id that is a whole number is that track;
//! any other id gets the next number in the order ids first appear, from
//! 0 — the same order in a bag and on the live topic, so the same
//! numbers. One topic's ids are all whole numbers or none are: mixed, a
//! number given to a named id could also be a numbered one's.
//!
//! The numbers given are kept in that order ([`TrackIds::named`]), so that
//! a reader that stops and starts again (a sensor resumed from its
//! journal) can be given them back ([`TrackIds::restore`]) and go on
//! numbering where it was, instead of from 0 again.

use std::collections::HashMap;

/// The most named (non-numeric) ids one topic may bring: each is kept for
/// the topic's life, and the ids are chosen by whoever publishes.
pub const MAX_NAMED_IDS: usize = 1 << 20;

/// The numbers given so far.
#[derive(Debug, Clone, Default)]
pub struct TrackIds {
    named: HashMap<String, u32>,
    /// The named ids in the order they were numbered: id `i` is track `i`.
    order: Vec<String>,
}

impl TrackIds {
    /// The track number of `id`, or why it has none.
    pub fn track(&mut self, id: &str) -> Result<u32, String> {
        if let Ok(number) = id.parse::<u32>() {
            return Ok(number);
        }
        if id.is_empty() {
            return Err("a detection with an empty id: the id is the track".into());
        }
        if let Some(&number) = self.named.get(id) {
            return Ok(number);
        }
        self.name(id)
    }

    /// Gives `id` (named, not yet numbered) the next number.
    fn name(&mut self, id: &str) -> Result<u32, String> {
        if self.order.len() >= MAX_NAMED_IDS {
            return Err(format!(
                "id {id:?}: {MAX_NAMED_IDS} named ids already, no number left for another"
            ));
        }
        let number = self.order.len() as u32;
        self.named.insert(id.to_string(), number);
        self.order.push(id.to_string());
        Ok(number)
    }

    /// The named ids numbered so far, in number order (id `i` is track
    /// `i`).
    pub fn named(&self) -> &[String] {
        &self.order
    }

    /// Takes back the numbers an earlier reader of the same topic gave
    /// (its [`TrackIds::named`]): `ids[i]` is track `i` again, and the next
    /// new id gets `ids.len()`. Only on a reader that has numbered nothing
    /// yet; an id that is a whole number, empty or listed twice is
    /// refused (no reader numbers those).
    pub fn restore(&mut self, ids: &[String]) -> Result<(), String> {
        if !self.order.is_empty() {
            return Err("track numbers restored after ids were numbered".into());
        }
        for id in ids {
            if id.is_empty() || id.parse::<u32>().is_ok() || self.named.contains_key(id) {
                *self = TrackIds::default();
                return Err(format!("id {id:?} cannot have been given a number"));
            }
            self.name(id)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_kept_and_names_numbered_in_order() {
        let mut ids = TrackIds::default();
        assert_eq!(ids.track("7"), Ok(7));
        assert_eq!(ids.track("b"), Ok(0));
        assert_eq!(ids.track("a"), Ok(1));
        assert_eq!(ids.track("b"), Ok(0));
        assert!(ids.track("").is_err());
        assert_eq!(ids.named(), ["b", "a"]);
    }

    #[test]
    fn restored_numbers_are_kept_and_new_names_numbered_after_them() {
        let mut first = TrackIds::default();
        for id in ["walker", "4", "cart", "walker"] {
            first.track(id).unwrap();
        }
        let mut again = TrackIds::default();
        again.restore(first.named()).unwrap();
        // Seen in another order after the restart: the numbers a reader
        // that never stopped gives.
        for id in ["late", "cart", "walker"] {
            assert_eq!(again.track(id), first.track(id), "{id}");
        }
        assert_eq!(again.track("late"), Ok(2));
        assert_eq!(again.named(), first.named());
        assert!(again.restore(&["x".into()]).is_err(), "numbered already");
        for bad in [&["a", "a"][..], &["a", "3"], &[""]] {
            let bad: Vec<String> = bad.iter().map(|s| s.to_string()).collect();
            let mut ids = TrackIds::default();
            assert!(ids.restore(&bad).is_err(), "{bad:?}");
            assert!(ids.named().is_empty(), "{bad:?}: nothing kept");
        }
    }
}
