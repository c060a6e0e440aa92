//! The separation step (Section IV-B): blind source separation of every
//! segment group OG_{i,j} into the separated segments SG_{i,j}.
//!
//! - [`fastica`] — FastICA itself, symmetric or deflation, on `nalgebra`.
//! - [`whitening`] — PCA whitening and the choice of how many components
//!   to keep.
//!
//! Per group and slot, only the whitened directions whose variance stands
//! clearly above the sensor noise are separated ([`SeparationSettings`]):
//! a group that hears nothing yields nothing, one that hears two targets
//! yields two segments. The noise variance is estimated blindly from the
//! data ([`estimate_noise_variance`]).

pub(crate) mod fastica;
pub(crate) mod whitening;

pub use fastica::{Algorithm, FastIca, FastIcaConfig, FastIcaError};
pub(crate) use whitening::whiten;
pub use whitening::Components;

use super::prepare::{segment_group, Segmentation, SensorGroup};
use crate::error::AcousticError;
use crate::field::SensorSignals;

/// How every segment group is separated.
#[derive(Debug, Clone, PartialEq)]
pub struct SeparationSettings {
    /// FastICA settings (its `components` and `seed` are set per group).
    pub ica: FastIcaConfig,
    /// Keep whitened directions with variance above this many times the
    /// noise variance. Pure noise in n_group channels over l_seg samples
    /// spreads up to (1 + √(n_group/l_seg))² ≈ 1.7 times it (Marchenko–
    /// Pastur), so 4 keeps sources and drops noise.
    pub keep_factor: f64,
    /// At most this many components per group.
    pub max_components: usize,
    /// Keep FastICA's last iterate when it hits the iteration cap (as
    /// scikit-learn does, with a warning) instead of dropping the group's
    /// segments for that slot. Counted either way.
    pub accept_unconverged: bool,
}

impl Default for SeparationSettings {
    fn default() -> Self {
        SeparationSettings {
            ica: FastIcaConfig::default(),
            keep_factor: 4.0,
            max_components: 10,
            accept_unconverged: true,
        }
    }
}

/// The separated segments of one time slot from all groups: each centred
/// and scaled to unit norm (so a dot product is a correlation), stored as
/// `f32` — ample for correlations, half the memory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SlotSegments {
    pub l_seg: usize,
    /// Row-major, `len() × l_seg`.
    pub data: Vec<f32>,
    /// The group each segment was separated from.
    pub group: Vec<u32>,
}

impl SlotSegments {
    pub fn len(&self) -> usize {
        self.group.len()
    }

    pub fn is_empty(&self) -> bool {
        self.group.is_empty()
    }

    /// Segment `i`, unit norm.
    pub fn segment(&self, i: usize) -> &[f32] {
        &self.data[i * self.l_seg..(i + 1) * self.l_seg]
    }

    /// Appends a segment, centring and normalising it; a constant segment
    /// is dropped.
    pub(crate) fn push(&mut self, group: u32, samples: impl Iterator<Item = f64>) {
        let v: Vec<f64> = samples.collect();
        debug_assert_eq!(v.len(), self.l_seg);
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let norm = v
            .iter()
            .map(|x| (x - mean) * (x - mean))
            .sum::<f64>()
            .sqrt();
        if !(norm > 0.0 && norm.is_finite()) {
            return;
        }
        self.data
            .extend(v.iter().map(|x| ((x - mean) / norm) as f32));
        self.group.push(group);
    }
}

/// Counts of what happened while separating.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeparationReport {
    /// Segment groups FastICA ran on.
    pub separations: usize,
    /// Segment groups with no direction above the noise floor.
    pub silent: usize,
    /// Separations that hit the iteration cap.
    pub not_converged: usize,
    /// Separated segments produced.
    pub segments: usize,
}

impl SeparationReport {
    pub fn add(&mut self, other: &SeparationReport) {
        self.separations += other.separations;
        self.silent += other.silent;
        self.not_converged += other.not_converged;
        self.segments += other.segments;
    }
}

/// A well-mixed 64-bit hash (SplitMix64's finaliser), for per-task seeds
/// that do not depend on scheduling.
pub(crate) fn mix_seed(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Separates every group's segment of time slot `slot`. `noise_variance`
/// is the sensor noise variance (see [`estimate_noise_variance`]).
pub fn separate_slot(
    signals: &SensorSignals,
    groups: &[SensorGroup],
    seg: &Segmentation,
    slot: usize,
    settings: &SeparationSettings,
    noise_variance: f64,
    seed: u64,
) -> Result<(SlotSegments, SeparationReport), AcousticError> {
    let mut out = SlotSegments {
        l_seg: seg.l_seg,
        ..SlotSegments::default()
    };
    let mut report = SeparationReport::default();
    let components = Components::AboveFloor {
        floor: settings.keep_factor * noise_variance,
        max: settings.max_components,
    };
    for (g, group) in groups.iter().enumerate() {
        let fail = |source| AcousticError::Separation {
            group: g,
            slot,
            source,
        };
        let x = segment_group(signals, group, seg, slot);
        let (whitening, z) = whiten(&x, &components).map_err(fail)?;
        if whitening.components() == 0 {
            report.silent += 1;
            continue;
        }
        let ica = FastIca::new(FastIcaConfig {
            components: components.clone(),
            seed: mix_seed(seed ^ mix_seed(((slot as u64) << 32) | g as u64)),
            ..settings.ica.clone()
        });
        report.separations += 1;
        let result = match ica.fit_whitened(whitening, z) {
            Ok(r) => r,
            Err(FastIcaError::NotConverged { partial, .. }) => {
                report.not_converged += 1;
                if !settings.accept_unconverged {
                    continue;
                }
                *partial
            }
            Err(e) => return Err(fail(e)),
        };
        for row in result.sources.row_iter() {
            out.push(g as u32, row.iter().copied());
        }
    }
    report.segments = out.len();
    Ok((out, report))
}

/// Estimates the sensor noise variance blindly: the smallest covariance
/// eigenvalue of a segment group that hears fewer sources than it has
/// sensors is noise, shrunk by about (1 − √(m/T))² (the lower Marchenko–
/// Pastur edge). The lower quartile of that statistic over a spread of
/// (group, slot) pairs ignores the groups that hear many sources.
pub fn estimate_noise_variance(
    signals: &SensorSignals,
    groups: &[SensorGroup],
    seg: &Segmentation,
    probes: usize,
) -> f64 {
    let slots = seg.slots();
    let total = groups.len() * slots;
    if total == 0 {
        return 0.0;
    }
    let probes = probes.clamp(1, total);
    let mut stats = Vec::with_capacity(probes);
    for p in 0..probes {
        // An even stride over all (group, slot) pairs, deterministic.
        let k = (p as u128 * total as u128 / probes as u128) as usize;
        let (g, j) = (k % groups.len(), (k / groups.len() + k) % slots);
        let x = segment_group(signals, &groups[g], seg, j);
        let m = x.nrows() as f64;
        let Ok((w, _)) = whiten(&x, &Components::All) else {
            continue;
        };
        let lambda_min = if w.eigenvalues.len() > 1 {
            *w.eigenvalues.last().unwrap_or(&0.0)
        } else {
            // One channel: its variance is all there is.
            w.eigenvalues[0]
        };
        let edge = (1.0 - (m / seg.l_seg as f64).sqrt()).powi(2).max(0.05);
        stats.push(lambda_min.max(0.0) / edge);
    }
    if stats.is_empty() {
        return 0.0;
    }
    stats.sort_by(f64::total_cmp);
    stats[stats.len() / 4]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{Field, FieldConfig};
    use crate::pipeline::prepare::nearest_groups;

    #[test]
    fn noise_floor_is_found_and_groups_yield_one_segment_per_heard_source() {
        let config = FieldConfig {
            sensors: 120,
            targets: 3,
            samples: 400,
            ..FieldConfig::default()
        };
        let field = Field::generate(&config, 3, 2).unwrap();
        let groups = nearest_groups(&field.sensors, 10).unwrap();
        let seg = Segmentation::new(100, 10, 400).unwrap();
        let var = estimate_noise_variance(&field.signals, &groups, &seg, 300);
        let truth = config.noise_std * config.noise_std;
        assert!((var / truth - 1.0).abs() < 0.3, "{var} vs {truth}");
        let (segs, report) = separate_slot(
            &field.signals,
            &groups,
            &seg,
            5,
            &SeparationSettings::default(),
            var,
            1,
        )
        .unwrap();
        assert_eq!(report.separations + report.silent, groups.len());
        assert_eq!(report.segments, segs.len());
        assert!(!segs.is_empty());
        // Every segment is unit norm.
        for i in 0..segs.len() {
            let n: f32 = segs.segment(i).iter().map(|v| v * v).sum();
            assert!((n - 1.0).abs() < 1e-4);
        }
        // A group that hears nothing yields nothing. (One that hears a
        // moving source may yield more than one segment for it: the gains
        // change within the segment, Section V-A.)
        let mid = seg.start(5) + 50;
        for (g, group) in groups.iter().enumerate() {
            let heard = field
                .paths
                .iter()
                .filter(|p| {
                    group.members.iter().any(|&m| {
                        field.sensors[m as usize].distance(p.positions[mid]) <= config.range + 10.0
                    })
                })
                .count();
            let got = segs.group.iter().filter(|&&x| x as usize == g).count();
            if heard == 0 {
                assert_eq!(got, 0, "group {g} hears nothing");
            }
            assert!(got <= 2 * heard, "group {g}: {got} segments, hears {heard}");
        }
        // The separated segments contain the true sources.
        let start = seg.start(5);
        for (t, src) in field.sources.iter().enumerate() {
            let heard_by_someone = groups.iter().any(|group| {
                group.members.iter().all(|&m| {
                    field.sensors[m as usize].distance(field.paths[t].positions[mid]) <= 150.0
                })
            });
            if !heard_by_someone {
                continue;
            }
            let truth: Vec<f64> = src[start..start + 100].to_vec();
            let best = (0..segs.len())
                .map(|i| {
                    let s: Vec<f64> = segs.segment(i).iter().map(|&v| f64::from(v)).collect();
                    crate::metrics::separation::correlation(&truth, &s).abs()
                })
                .fold(0.0, f64::max);
            assert!(best > 0.9, "source {t}: best |corr| {best}");
        }
    }
}
