//! # Acoustic tracking of indistinguishable targets
//!
//! Zhu, Vikram, Fu & Guan, *On Non-Cooperative Multiple-Target Tracking
//! With Wireless Sensor Networks* (IEEE TMC 2014): sensors hear only the
//! sum of the sources around them; blind source separation (FastICA)
//! recovers the individual signals, and the sensing ranges of the sensor
//! groups that hear the same recovered signal locate its target. The
//! output is a track per target and the `mix` events where two tracks come
//! close — indistinguishable targets in, tracks and "who is who" events
//! out, for the property and identity beliefs.
//!
//! A map (private modules; what the examples, benches and `idmesh-deploy`
//! use is re-exported below, by concern):
//! - `field` — the simulated field of Section VI-A: sensors, target
//!   paths, attenuation, the aggregate signal at every sensor.
//! - `source` — what the targets emit: synthetic chirps, AR sources,
//!   real recordings (WAV/Ogg).
//! - `pipeline` — the six steps of Section IV: prepare, separate
//!   (FastICA), cluster, select, intersect, vote and link.
//! - `metrics` — error distance and coverage (Section VI-B), separation
//!   quality (Amari index).
//! - `resolution` — Theorems 5.3 and 5.5.
//! - `run` — the whole pipeline: [`run()`] → [`AcousticResult`].
//! - `trace` — the result as an idmesh trace (`move` and `mix` lines).
//! - `config` — every setting and its default; `error` — what fails.
//!
//! ```no_run
//! use idmesh_acoustic::{run, write_trace, AcousticConfig};
//!
//! let config = AcousticConfig::paper(1000, 10, 42); // sensors, targets, seed
//! let result = run(&config, &mut |done, total| eprint!("\r{done}/{total}")).unwrap();
//! println!("mean error {:.1} m, coverage {:.0} %",
//!          result.metrics.mean_error, 100.0 * result.metrics.coverage);
//! let file = std::io::BufWriter::new(std::fs::File::create("acoustic.jsonl").unwrap());
//! write_trace(&result, file, "acoustic.jsonl").unwrap();
//! ```

/// The line of docs/acoustic-trends.md that says which code made it: the
/// digest of the tracker's sources and the `acoustic_trends` example
/// (build.rs).
pub fn trends_stamp_line() -> String {
    format!(
        "<!-- idmesh acoustic stamp: sources {} -->",
        env!("IDMESH_ACOUSTIC_STAMP")
    )
}

mod config;
mod error;
mod field;
mod metrics;
mod parallel;
mod pipeline;
mod resolution;
mod run;
mod source;
mod trace;

// Settings, the whole run, and its result as an idmesh trace.
pub use config::{AcousticConfig, PipelineConfig};
pub use error::AcousticError;
pub use run::{run, run_variants, AcousticResult};
pub use trace::write_trace;
// The simulated field and what its targets emit.
pub use field::{Field, PathSpec};
pub use source::{ar::ar_source, chirp::chirp_song, ArParams, ChirpParams, SourceKind};
// The pipeline's steps one at a time, for diagnostics and benches.
pub use pipeline::cluster::cluster_slot;
pub use pipeline::prepare::{nearest_groups, Segmentation};
pub use pipeline::select::{link_layer, select_cts, SelectSettings};
pub use pipeline::separate::{
    estimate_noise_variance, separate_slot, Algorithm, Components, FastIca, FastIcaConfig,
    FastIcaError,
};
// Separation quality, and the resolution theorems (Section V).
pub use metrics::separation::{amari_index, max_abs_correlations};
pub use resolution::{average_resolution, group_radius};

#[cfg(test)]
mod stamp_tests {
    #[test]
    fn the_committed_trends_were_generated_by_the_code_as_it_is() {
        // Any change to the tracker or to the trends program changes the
        // stamp: regenerate docs/acoustic-trends.md and commit it.
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/acoustic-trends.md");
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            committed.contains(&super::trends_stamp_line()),
            "docs/acoustic-trends.md is stale: it does not carry {:?}; regenerate it with \
             `cargo run --release -p idmesh-acoustic --example acoustic_trends`",
            super::trends_stamp_line()
        );
    }
}
