//! `idmesh` — one binary, one subcommand per role (see [`cli`]).
//!
//! Errors end the process with status 1 and one line on stderr, `FILE:LINE:
//! reason` when a trace line is at fault; logs go to stderr too (`RUST_LOG`,
//! default `warn`); stdout carries only results.

mod acoustic;
mod bench;
mod cli;
mod eval;
mod logging;
mod replay;
mod replay_identity;
mod runtime;
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
        Command::Replay(mut args) => {
            let stdout = BufWriter::new(std::io::stdout().lock());
            args.method = Some(replay::method_for(&args.trace, args.method)?);
            match args.method().identity() {
                Some(method) => {
                    let options = replay_identity::IdentityReplayOptions {
                        trace: args.trace,
                        method,
                        marginals: args.marginals,
                        bits: args.bits,
                        budget: args.budget,
                        seed: args.seed.unwrap_or(0),
                        samples: args.samples,
                    };
                    replay_identity::run(&options, stdout)
                }
                None => replay::run(&args, stdout),
            }
        }
        Command::Simulate(args) => simulate::run(&args),
        Command::Acoustic(args) => acoustic::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Sensor(args) => {
            runtime::roles::run(runtime::roles::Role::Sensor, &args.config, &args.name)
        }
        Command::Leader(args) => {
            runtime::roles::run(runtime::roles::Role::Leader, &args.config, &args.name)
        }
        Command::Coordinator(args) => {
            runtime::roles::run(runtime::roles::Role::Coordinator, &args.config, &args.name)
        }
        Command::Up(args) => runtime::launch::up(&args.config, args.host.as_deref()),
        Command::Demo(args) => runtime::launch::demo(&runtime::launch::DemoOptions {
            events: args.events,
            targets: args.targets,
            red: args.red,
            seed: args.seed,
            rate: args.rate,
            dir: args.dir,
        }),
        Command::Query(args) => runtime::query::run(&args.options()?),
        Command::Bench(args) => bench::run(&bench::BenchOptions {
            targets: args.targets,
            red: args.red,
            duration: args.duration,
            seed: args.seed,
            leaders: args.leaders,
            budget: args.budget,
            queries: args.queries,
            stream_rate: args.stream_rate,
            dir: args.dir,
            out: args.out,
        }),
    }
}
