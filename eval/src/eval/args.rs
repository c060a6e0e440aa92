//! The command line of `idmesh eval`: the preset, where the results go,
//! workers, seeds and extra methods (a `clap` argument group, parsed by the
//! binary).

use clap::{Args, ValueEnum};
use std::path::PathBuf;

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct EvalArgs {
    /// How big a grid: `quick` (a tiny grid in seconds, for tests) or
    /// `full` (the tables and figures of docs/results.md).
    #[arg(long, value_enum, default_value_t = Preset::Quick)]
    pub preset: Preset,
    /// Where results.md and the SVG plots go (created if missing; default:
    /// a new folder target/idmesh-eval/<preset>-<N>, so nothing is
    /// overwritten — `--out-dir docs` regenerates the committed results).
    #[arg(long, value_name = "DIR")]
    pub out_dir: Option<PathBuf>,
    /// Worker threads for the grid.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: u16,
    /// Seeds per scenario (default: 1 for quick, 5 for full).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    pub seeds: Option<u16>,
    /// More methods for every Table III point, by registry name
    /// (exact, order1, order3, threshold:B, overcomplete:B, distributed:B,
    /// particles:P, factored), comma-separated.
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub methods: Vec<String>,
}

/// Grid sizes of `eval`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Preset {
    /// A tiny grid that runs in seconds: every table and plot, few points.
    Quick,
    /// The grid behind docs/results.md (under 30 minutes on 2 cores).
    Full,
}
