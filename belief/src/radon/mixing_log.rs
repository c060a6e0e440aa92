//! The mixing log of Section 5.4: for every track, the tracks it mixed with
//! since its property was last observed. The distributed conditioning rule
//! (Algorithm 5) only grows sets that meet this log; an observation of the
//! track clears its entry.

use smallvec::SmallVec;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(from = "Vec<Vec<u32>>", into = "Vec<Vec<u32>>")]
pub struct MixingLog {
    partners: Vec<SmallVec<[u32; 4]>>,
}

/// A log as a snapshot writes it: each track's partners.
impl From<MixingLog> for Vec<Vec<u32>> {
    fn from(log: MixingLog) -> Self {
        log.partners.into_iter().map(|p| p.to_vec()).collect()
    }
}

impl From<Vec<Vec<u32>>> for MixingLog {
    fn from(partners: Vec<Vec<u32>>) -> Self {
        MixingLog {
            partners: partners.into_iter().map(SmallVec::from_vec).collect(),
        }
    }
}

impl MixingLog {
    pub fn new(tracks: usize) -> Self {
        MixingLog {
            partners: vec![SmallVec::new(); tracks],
        }
    }

    pub fn record(&mut self, a: u32, b: u32) {
        for (t, other) in [(a, b), (b, a)] {
            let list = &mut self.partners[t as usize];
            if !list.contains(&other) {
                list.push(other);
            }
        }
    }

    /// The tracks `t` mixed with since it was last observed.
    pub fn partners(&self, t: u32) -> &[u32] {
        &self.partners[t as usize]
    }

    pub fn clear(&mut self, t: u32) {
        self.partners[t as usize].clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_both_directions_once_and_clears() {
        let mut log = MixingLog::new(4);
        log.record(0, 2);
        log.record(2, 0);
        log.record(2, 3);
        assert_eq!(log.partners(2), &[0, 3]);
        assert_eq!(log.partners(0), &[2]);
        log.clear(2);
        assert!(log.partners(2).is_empty());
        assert_eq!(log.partners(3), &[2]);
    }
}
