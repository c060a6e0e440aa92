//! The preparation step (Section IV-A, Figs. 2 and 3): sensors are grouped
//! in space — one group per sensor, made of it and its n_group − 1 nearest
//! neighbours — and recordings are cut in time into overlapping segments of
//! l_seg samples, l_step apart. Both redundancies are deliberate: a source
//! separated by several neighbouring groups (spatial) and in successive
//! overlapping slots (temporal) is what the clustering and selection steps
//! recognise as real.

use crate::error::AcousticError;
use crate::field::SensorSignals;
use idmesh_sim::Vec2;
use nalgebra::DMatrix;

/// A sensor group: its members (sensor indices, ascending) and where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorGroup {
    pub members: Vec<u32>,
    /// Mean position of the members.
    pub center: Vec2,
    /// Largest distance of a member from the centre (the r of Section
    /// V-B, per group).
    pub radius: f64,
}

/// One group per sensor — the sensor and its `n_group − 1` nearest
/// neighbours — with duplicates (two sensors whose neighbourhoods are the
/// same set) kept once: they would separate the same mixtures twice.
pub fn nearest_groups(sensors: &[Vec2], n_group: usize) -> Result<Vec<SensorGroup>, AcousticError> {
    if n_group == 0 || n_group > sensors.len() {
        return Err(AcousticError::Config(format!(
            "n_group must be in 1..={} (the number of sensors), got {n_group}",
            sensors.len()
        )));
    }
    let mut seen = rustc_hash::FxHashSet::default();
    let mut groups = Vec::new();
    let mut order: Vec<(f64, u32)> = Vec::with_capacity(sensors.len());
    for &s in sensors {
        order.clear();
        order.extend(
            sensors
                .iter()
                .enumerate()
                .map(|(j, &p)| (s.distance_sq(p), j as u32)),
        );
        // Ties broken by index, so grouping is deterministic.
        order.select_nth_unstable_by(n_group - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut members: Vec<u32> = order[..n_group].iter().map(|&(_, j)| j).collect();
        members.sort_unstable();
        if !seen.insert(members.clone()) {
            continue;
        }
        let center = members
            .iter()
            .fold(Vec2::ZERO, |acc, &m| acc + sensors[m as usize])
            * (1.0 / n_group as f64);
        let radius = members
            .iter()
            .map(|&m| sensors[m as usize].distance(center))
            .fold(0.0, f64::max);
        groups.push(SensorGroup {
            members,
            center,
            radius,
        });
    }
    Ok(groups)
}

/// The time slots: slot j covers samples `j·l_step .. j·l_step + l_seg`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Segmentation {
    pub l_seg: usize,
    pub l_step: usize,
    pub samples: usize,
}

impl Segmentation {
    /// Checks that slots overlap (l_step < l_seg, or the link correlation
    /// of Section IV-D has nothing to compare) and fit the recording.
    pub fn new(l_seg: usize, l_step: usize, samples: usize) -> Result<Self, AcousticError> {
        if l_seg < 4 || l_step == 0 || l_step >= l_seg {
            return Err(AcousticError::Config(format!(
                "need 0 < l_step < l_seg and l_seg ≥ 4, got l_seg = {l_seg}, l_step = {l_step}"
            )));
        }
        if l_seg > samples {
            return Err(AcousticError::Config(format!(
                "segment length {l_seg} exceeds the {samples}-sample recording"
            )));
        }
        Ok(Segmentation {
            l_seg,
            l_step,
            samples,
        })
    }

    /// Number of time slots v.
    pub(crate) fn slots(&self) -> usize {
        (self.samples - self.l_seg) / self.l_step + 1
    }

    /// First sample of slot `j`.
    pub fn start(&self, j: usize) -> usize {
        j * self.l_step
    }

    /// Middle of slot `j`, in samples (where its path fragment is dated).
    pub fn middle(&self, j: usize) -> f64 {
        (j * self.l_step) as f64 + (self.l_seg as f64 - 1.0) / 2.0
    }

    /// Length of the common part of two successive slots.
    #[cfg(test)]
    pub(crate) fn overlap(&self) -> usize {
        self.l_seg - self.l_step
    }
}

/// The segment group OG_{i,j}: the recordings of `group`'s members during
/// slot `slot`, one row per member (n_group × l_seg).
pub(crate) fn segment_group(
    signals: &SensorSignals,
    group: &SensorGroup,
    seg: &Segmentation,
    slot: usize,
) -> DMatrix<f64> {
    let start = seg.start(slot);
    DMatrix::from_fn(group.members.len(), seg.l_seg, |p, k| {
        signals.sensor(group.members[p] as usize)[start + k]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_are_nearest_neighbourhoods_without_duplicates() {
        // Two clusters of three sensors far apart.
        let sensors = vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 1.0),
            Vec2::new(100.0, 0.0),
            Vec2::new(101.0, 0.0),
            Vec2::new(100.0, 1.0),
        ];
        let groups = nearest_groups(&sensors, 3).unwrap();
        assert_eq!(groups.len(), 2);
        assert_eq!(groups[0].members, vec![0, 1, 2]);
        assert_eq!(groups[1].members, vec![3, 4, 5]);
        assert!((groups[1].center.x - 100.333).abs() < 1e-3);
        assert!(nearest_groups(&sensors, 7).is_err());
        let single = nearest_groups(&sensors, 1).unwrap();
        assert_eq!(single.len(), 6);
    }

    #[test]
    fn slots_overlap_as_in_fig_3() {
        let s = Segmentation::new(100, 10, 1000).unwrap();
        assert_eq!(s.slots(), 91);
        assert_eq!(s.start(90) + 100, 1000);
        assert_eq!(s.overlap(), 90);
        assert!(Segmentation::new(100, 100, 1000).is_err());
        assert!(Segmentation::new(100, 10, 50).is_err());
        let signals = SensorSignals {
            sensors: 2,
            samples: 6,
            data: (0..12).map(f64::from).collect(),
        };
        let g = SensorGroup {
            members: vec![1, 0],
            center: Vec2::ZERO,
            radius: 0.0,
        };
        let s = Segmentation::new(4, 2, 6).unwrap();
        let m = segment_group(&signals, &g, &s, 1);
        assert_eq!(
            m.row(0).iter().copied().collect::<Vec<_>>(),
            vec![8.0, 9.0, 10.0, 11.0]
        );
        assert_eq!(
            m.row(1).iter().copied().collect::<Vec<_>>(),
            vec![2.0, 3.0, 4.0, 5.0]
        );
    }
}
