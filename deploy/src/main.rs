//! `idmesh` — one binary, one subcommand per role (see [`cli`]).
//!
//! Errors end the process with status 1 and one line on stderr, `FILE:LINE:
//! reason` when a trace line is at fault; logs go to stderr too (`RUST_LOG`,
//! default `warn`); stdout carries only results.

mod acoustic;
mod cli;
mod eval;
mod logging;
mod replay;
mod simulate;

use clap::Parser;
use cli::{Cli, Command};
use std::io::{BufWriter, Write};
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    logging::init();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            let _ = writeln!(std::io::stderr(), "{error:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Replay(args) => {
            let stdout = BufWriter::new(std::io::stdout().lock());
            replay::run(&args, stdout)
        }
        Command::Simulate(args) => simulate::run(&args),
        Command::Acoustic(args) => acoustic::run(&args),
        Command::Eval(args) => eval::run(&args),
    }
}
