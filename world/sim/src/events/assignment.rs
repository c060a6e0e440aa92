//! Which target is on which track. The tracker follows positions; when two
//! targets mix it cannot tell them apart and, with the mix's swap
//! probability, continues each track on the other target. The ground truth
//! of the trace follows that draw: after an exchange, the track that
//! followed target i follows target j and vice versa, so which tracks carry
//! red targets changes. Positions (`move` lines) are those of the target a
//! track currently follows — at the moment of an exchange the two targets
//! are within the mixing distance, so a track's path jumps by at most that.

/// A bijection between targets (the things that move) and tracks (the
/// tracker's labels). Starts as the identity: track t follows target t.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Assignment {
    target_on_track: Vec<u32>,
    track_of_target: Vec<u32>,
}

impl Assignment {
    pub(crate) fn identity(n: usize) -> Self {
        let ids: Vec<u32> = (0..n as u32).collect();
        Assignment {
            target_on_track: ids.clone(),
            track_of_target: ids,
        }
    }

    /// The track following `target`.
    pub(crate) fn track_of(&self, target: usize) -> u32 {
        self.track_of_target[target]
    }

    /// The target `track` follows.
    pub(crate) fn target_on(&self, track: usize) -> u32 {
        self.target_on_track[track]
    }

    /// The tracks of targets `i` and `j` are exchanged.
    pub(crate) fn exchange_targets(&mut self, i: usize, j: usize) {
        let (ti, tj) = (self.track_of_target[i], self.track_of_target[j]);
        self.track_of_target.swap(i, j);
        self.target_on_track[ti as usize] = j as u32;
        self.target_on_track[tj as usize] = i as u32;
    }

    /// The tracks following the targets with `is_red[target]`, ascending.
    pub(crate) fn red_tracks(&self, is_red: &[bool]) -> Vec<u32> {
        let mut red: Vec<u32> = is_red
            .iter()
            .enumerate()
            .filter(|(_, &r)| r)
            .map(|(i, _)| self.track_of_target[i])
            .collect();
        red.sort_unstable();
        red
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exchanges_keep_a_bijection() {
        let mut a = Assignment::identity(4);
        a.exchange_targets(0, 2);
        a.exchange_targets(2, 3);
        // Target 0 on track 2, target 2 on track 3, target 3 on track 0.
        assert_eq!(a.track_of(0), 2);
        assert_eq!(a.track_of(2), 3);
        assert_eq!(a.track_of(3), 0);
        for t in 0..4 {
            assert_eq!(a.track_of(a.target_on(t) as usize), t as u32);
        }
        assert_eq!(a.red_tracks(&[true, false, false, true]), vec![0, 2]);
    }
}
