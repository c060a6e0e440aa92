//! A tracker's track ids as the belief's track numbers. A ROS message
//! names a track by a string (a detection's `id`, an object's UUID); the
//! belief's tracks are `0..n`. An id that is a whole number is that track;
//! any other id gets the next number in the order ids first appear, from
//! 0 — the same order in a bag and on the live topic, so the same
//! numbers. One topic's ids are all whole numbers or none are: mixed, a
//! number given to a named id could also be a numbered one's.

use std::collections::HashMap;

/// The most named (non-numeric) ids one topic may bring: each is kept for
/// the topic's life, and the ids are chosen by whoever publishes.
pub const MAX_NAMED_IDS: usize = 1 << 20;

/// The numbers given so far.
#[derive(Debug, Clone, Default)]
pub struct TrackIds {
    named: HashMap<String, u32>,
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
        if self.named.len() >= MAX_NAMED_IDS {
            return Err(format!(
                "id {id:?}: {MAX_NAMED_IDS} named ids already, no number left for another"
            ));
        }
        let number = self.named.len() as u32;
        self.named.insert(id.to_string(), number);
        Ok(number)
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
    }
}
