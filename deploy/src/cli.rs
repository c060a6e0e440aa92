//! The command line: one subcommand per role idmesh plays. Parsing only;
//! what a subcommand does lives in its own module.

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// idmesh keeps track of who is who among moving targets: a belief over
/// which tracks carry a property, answered on demand.
#[derive(Debug, Parser)]
#[command(name = "idmesh", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Replay a trace through one filter offline: one JSON line with the
    /// answers at every `truth` line, then a summary line.
    Replay(ReplayArgs),
}

#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// The trace to replay (JSON Lines, shared/spec/trace.md).
    #[arg(long, value_name = "FILE")]
    pub trace: PathBuf,

    /// The filter to run.
    #[arg(long, value_enum, default_value_t = Method::Overcomplete)]
    pub method: Method,

    /// The most coefficients the Radon belief may hold after an event
    /// (overcomplete: optional, none = exact; threshold: required).
    #[arg(long, value_name = "N", value_parser = parse_budget)]
    pub budget: Option<usize>,

    /// Condition with the distributed rule of Section 5.4 (Radon methods
    /// only): an approximation that touches only the sets an observation's
    /// track mixed into since it was last observed.
    #[arg(long)]
    pub distributed_rule: bool,
}

/// The filters `replay` can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Radon belief on the overcomplete basis; OMP then thresholding once
    /// --budget is exceeded (exact without --budget).
    Overcomplete,
    /// Radon belief pruned to --budget coefficients by thresholding alone.
    Threshold,
    /// The exact dense filter over every red set (small fields only).
    Exact,
    /// First-order Radon projection (Table III baseline).
    Order1,
    /// Second-order Radon projection (Table III baseline).
    Order2,
    /// Third-order Radon projection (Table III baseline).
    Order3,
}

impl Method {
    /// The name on the command line and in the summary.
    pub fn name(self) -> &'static str {
        match self {
            Method::Overcomplete => "overcomplete",
            Method::Threshold => "threshold",
            Method::Exact => "exact",
            Method::Order1 => "order1",
            Method::Order2 => "order2",
            Method::Order3 => "order3",
        }
    }

    /// Whether the method is the Radon engine (and so takes --budget and
    /// --distributed-rule).
    pub fn is_radon(self) -> bool {
        matches!(self, Method::Overcomplete | Method::Threshold)
    }
}

fn parse_budget(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(0) => Err("the budget must be at least 1 coefficient".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(format!("not a whole number of coefficients: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_well_formed() {
        Cli::command().debug_assert();
    }

    #[test]
    fn method_names_match_the_command_line() {
        for method in Method::value_variants() {
            let value = method.to_possible_value().unwrap();
            assert_eq!(value.get_name(), method.name());
        }
    }

    #[test]
    fn replay_arguments() {
        let cli = Cli::try_parse_from([
            "idmesh",
            "replay",
            "--trace",
            "t.jsonl",
            "--method",
            "threshold",
            "--budget",
            "64",
            "--distributed-rule",
        ])
        .unwrap();
        let Command::Replay(args) = cli.command;
        assert_eq!(args.method, Method::Threshold);
        assert_eq!(args.budget, Some(64));
        assert!(args.distributed_rule);
        assert!(
            Cli::try_parse_from(["idmesh", "replay", "--trace", "t", "--budget", "0"]).is_err()
        );
    }
}
