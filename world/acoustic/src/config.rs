//! Every setting of an acoustic tracking run, with the paper's defaults
//! (Section VI-A) where it gives them and stated choices where it does not.

use super::error::AcousticError;
use super::field::FieldConfig;
use super::pipeline::cluster::Linkage;
use super::pipeline::separate::SeparationSettings;

/// Settings of the six pipeline steps.
///
/// | field | default | paper |
/// |---|---|---|
/// | `n_group` | 10 | 10 |
/// | `l_seg` | 100 samples | 100 |
/// | `l_step` | 10 samples | 10 |
/// | `n_slot` | 5 slots per CTS | not given |
/// | `clusters_per_target` | 2 (2K clusters per slot) | 2 |
/// | `linkage` | average | agglomerative, linkage not given |
/// | `separation` | FastICA logcosh, symmetric, tol 10⁻⁴, 200 iterations; directions above 4× the noise floor | FastICA |
/// | `link_candidates` | 8 strongest links per segment | (all) |
/// | `min_link` | mean link correlation ≥ 0.9 along the chain | ranks by it (see `pipeline::select`) |
/// | `min_support` | heard by ≥ 3 groups | not given |
/// | `aggregate_r2` | 0.9: a candidate two others explain is an aggregate | not given |
/// | `same_source` | \|corr\| ≥ 0.9: two segments are one source (support, duplicates) | not given |
/// | `hear_threshold` | \|corr\| ≥ 0.7: a group hears a selected segment (intersection) | "highly correlated" |
/// | `exclude_silent` | true: of the intersection, keep the points the fewest *non*-hearing groups' ranges cover | no: hearing groups only |
/// | `silent_slack` | 1: the fewest and one more (a group can miss a source it should hear) | — |
/// | `tile` | 5 m | 5 m |
/// | `vote_tolerance` | 0 m | 0 (overlapping areas) |
/// | `link_gate` | 50 m (+ `max_speed` × elapsed samples) | none |
/// | `max_speed` | 0.15 m/sample | speed limit, assumption (4) |
#[derive(Debug, Clone, PartialEq)]
pub struct PipelineConfig {
    pub n_group: usize,
    pub l_seg: usize,
    pub l_step: usize,
    pub n_slot: usize,
    pub clusters_per_target: usize,
    pub linkage: Linkage,
    pub separation: SeparationSettings,
    pub link_candidates: usize,
    pub min_link: f64,
    pub min_support: u32,
    pub aggregate_r2: f64,
    pub same_source: f64,
    pub hear_threshold: f64,
    pub exclude_silent: bool,
    /// With `exclude_silent`: also keep points that this many more silent
    /// groups cover than the fewest.
    pub silent_slack: u32,
    pub tile: f64,
    pub vote_tolerance: f64,
    pub link_gate: f64,
    pub max_speed: f64,
    /// (group, slot) pairs probed to estimate the noise floor.
    pub noise_probes: usize,
}

impl PipelineConfig {
    /// The paper's intersection as written: the ranges of the hearing
    /// groups only. The default also removes the ranges of the groups that
    /// do not hear (`exclude_silent`, see `pipeline::intersect` and
    /// docs/design/acoustic.md).
    pub fn paper_intersection(mut self) -> Self {
        self.exclude_silent = false;
        self
    }
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            n_group: 10,
            l_seg: 100,
            l_step: 10,
            n_slot: 5,
            clusters_per_target: 2,
            linkage: Linkage::Average,
            separation: SeparationSettings::default(),
            link_candidates: 8,
            min_link: 0.9,
            min_support: 3,
            aggregate_r2: 0.9,
            same_source: 0.9,
            hear_threshold: 0.7,
            exclude_silent: true,
            silent_slack: 1,
            tile: 5.0,
            vote_tolerance: 0.0,
            link_gate: 50.0,
            max_speed: 0.15,
            noise_probes: 1000,
        }
    }
}

/// How the trace is written.
#[derive(Debug, Clone, PartialEq)]
pub struct OutputConfig {
    /// Two estimated paths closer than this (metres) make a `mix` line.
    pub mix_distance: f64,
    /// They must separate beyond `release_factor × mix_distance` before
    /// they can mix again (hysteresis, as the scenario generator does).
    pub release_factor: f64,
    /// The `swap` probability of a mix: the targets are indistinguishable,
    /// so ½ by default.
    pub swap: f64,
    /// Samples per second: trace times are sample indices divided by this
    /// (1 = times in samples, the unit of the paper's speeds).
    pub sample_rate: f64,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            mix_distance: 30.0,
            release_factor: 1.25,
            swap: 0.5,
            sample_rate: 1.0,
        }
    }
}

/// A whole run: the field, the pipeline, the output, the seed and the
/// number of worker threads.
#[derive(Debug, Clone, PartialEq)]
pub struct AcousticConfig {
    pub field: FieldConfig,
    pub pipeline: PipelineConfig,
    pub output: OutputConfig,
    pub seed: u64,
    /// Worker threads (the caller's thread counts as one); default 2.
    pub threads: usize,
}

impl Default for AcousticConfig {
    fn default() -> Self {
        AcousticConfig {
            field: FieldConfig::default(),
            pipeline: PipelineConfig::default(),
            output: OutputConfig::default(),
            seed: 0,
            threads: 2,
        }
    }
}

impl AcousticConfig {
    /// The paper's default field with `sensors` sensors and `targets`
    /// targets.
    pub fn paper(sensors: usize, targets: usize, seed: u64) -> Self {
        let mut c = AcousticConfig::default();
        c.field.sensors = sensors;
        c.field.targets = targets;
        c.seed = seed;
        c
    }

    /// Checks every setting; the error names the first bad one.
    pub fn validate(&self) -> Result<(), AcousticError> {
        self.field.validate()?;
        let p = &self.pipeline;
        let bad = |what: String| Err(AcousticError::Config(what));
        if p.n_group == 0 || p.n_group > self.field.sensors {
            return bad(format!(
                "n_group must be in 1..={}, got {}",
                self.field.sensors, p.n_group
            ));
        }
        if p.n_slot < 2 {
            return bad(format!(
                "n_slot must be ≥ 2 (a CTS links slots), got {}",
                p.n_slot
            ));
        }
        if p.clusters_per_target == 0 {
            return bad("clusters_per_target must be ≥ 1".into());
        }
        if p.link_candidates == 0 {
            return bad("link_candidates must be ≥ 1".into());
        }
        if !(0.0..=1.0).contains(&p.min_link) {
            return bad(format!("min_link must be in [0, 1], got {}", p.min_link));
        }
        if !(0.0..=1.0).contains(&p.same_source) {
            return bad(format!(
                "same_source must be in [0, 1], got {}",
                p.same_source
            ));
        }
        if !(0.0..=1.0).contains(&p.hear_threshold) {
            return bad(format!(
                "hear_threshold must be in [0, 1], got {}",
                p.hear_threshold
            ));
        }
        if !(p.tile.is_finite() && p.tile > 0.0) {
            return bad(format!("tile must be > 0 m, got {}", p.tile));
        }
        for (name, v) in [
            ("vote_tolerance", p.vote_tolerance),
            ("link_gate", p.link_gate),
            ("max_speed", p.max_speed),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("{name} must be ≥ 0, got {v}"));
            }
        }
        if !(p.separation.keep_factor.is_finite() && p.separation.keep_factor > 0.0)
            || p.separation.max_components == 0
        {
            return bad(format!(
                "separation keep_factor must be > 0 and max_components ≥ 1, got {} and {}",
                p.separation.keep_factor, p.separation.max_components
            ));
        }
        p.separation
            .ica
            .validate()
            .map_err(|e| AcousticError::Config(e.to_string()))?;
        let o = &self.output;
        if !(o.mix_distance.is_finite() && o.mix_distance > 0.0) {
            return bad(format!(
                "mix_distance must be > 0 m, got {}",
                o.mix_distance
            ));
        }
        if !(o.release_factor.is_finite() && o.release_factor >= 1.0) {
            return bad(format!(
                "release_factor must be ≥ 1, got {}",
                o.release_factor
            ));
        }
        if !(0.0..=1.0).contains(&o.swap) {
            return bad(format!("swap must be in [0, 1], got {}", o.swap));
        }
        if !(o.sample_rate.is_finite() && o.sample_rate > 0.0) {
            return bad(format!("sample_rate must be > 0, got {}", o.sample_rate));
        }
        if self.threads == 0 {
            return bad("threads must be ≥ 1".into());
        }
        super::pipeline::prepare::Segmentation::new(p.l_seg, p.l_step, self.field.samples)?;
        Ok(())
    }
}
