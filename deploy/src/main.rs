//! `idmesh` — one binary, one subcommand per role (see [`cli`]). The
//! offline tools, `replay` and `eval`, are the `idmesh-eval` crate; the
//! roles of a deployment are their own crates, started by [`runtime`].
//!
//! Errors end the process with status 1 and one line on stderr, `FILE:LINE:
//! reason` when a trace line is at fault; logs go to stderr too (`RUST_LOG`,
//! default `warn`); stdout carries only results.

mod acoustic;
mod bench;
mod cli;
mod emit;
mod extract;
mod logging;
mod simulate;

// The library's runtime, reached as `crate::runtime` from the binary's
// own modules too.
use idmesh_deploy::runtime;

use clap::Parser;
use cli::{Cli, Command};
use std::io::{BufWriter, Write};
use std::process::ExitCode;

/// mimalloc rather than glibc's allocator: a deployment's messages are
/// decoded on Zenoh's threads and dropped on the role's, and glibc paid
/// for that in arena locks and heap trimming. Measured in `idmesh bench`
/// (10,000 targets, runs paired back to back): 10-15% less CPU in every
/// process, one leader or four.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

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
        Command::Replay(cli::ReplayCommand {
            mut args,
            max_errors,
        }) => {
            // The twin of sensors that extract replays the reports'
            // events, extracted into a file of its own that is removed
            // whatever happens (dropped on every path out).
            let mut extracted = None;
            if let Some(path) = args.topology.take() {
                let topology = runtime::topology::Topology::load(&path)?;
                topology.replay_twin(&mut args)?;
                extracted = extract::twin_trace(&topology, &args.trace, max_errors)?;
                if let Some(trace) = &extracted {
                    args.trace = trace.path().to_path_buf();
                }
            }
            let stdout = BufWriter::new(std::io::stdout().lock());
            let replayed = idmesh_eval::replay::dispatch(&args, stdout);
            drop(extracted);
            replayed
        }
        Command::Simulate(args) => simulate::run(&args),
        Command::Extract(args) => extract::run(&args),
        Command::Acoustic(args) => acoustic::run(&args),
        Command::Eval(args) => idmesh_eval::eval::run(&args),
        Command::Sensor(args) => runtime::roles::run(
            runtime::roles::Role::Sensor {
                stdin: args.stdin,
                max_errors: args.max_errors,
            },
            &args.role.config,
            &args.role.name,
        ),
        Command::Leader(args) => {
            runtime::roles::run(runtime::roles::Role::Leader, &args.config, &args.name)
        }
        Command::Coordinator(args) => {
            runtime::roles::run(runtime::roles::Role::Coordinator, &args.config, &args.name)
        }
        Command::Voter(args) => {
            runtime::roles::run(runtime::roles::Role::Voter, &args.config, &args.name)
        }
        Command::SensorStandby(args) => runtime::roles::run(
            runtime::roles::Role::SensorStandby,
            &args.config,
            &args.name,
        ),
        Command::Up(args) if args.emit.is_some() => emit::run(&args),
        Command::Up(args) => runtime::launch::up(&args.config, args.host.as_deref()),
        Command::Demo(args) => runtime::launch::demo(&args.options()?),
        Command::Query(args) => runtime::query::run(&args.options()?),
        Command::Web(args) => runtime::web::run(&args.options()?),
        Command::Bench(args) => bench::run(&bench::BenchOptions {
            targets: args.targets,
            red: args.red,
            duration: args.duration,
            seed: args.seed,
            leaders: args.leaders,
            belief: args.belief,
            window: args.window,
            budget: args.budget,
            repeat: args.repeat,
            queries: args.queries,
            stream_rate: args.stream_rate,
            dir: args.dir,
            out: args.out,
            ingest: args.ingest,
            journal: args.journal,
            accuracy: args.accuracy.then_some(bench::Crowds {
                sizes: args.sizes,
                starts: args.starts,
                seeds: args.seeds as usize,
            }),
            extraction: args.extraction,
            identity: args.identity,
            replication: args.replication,
            standbys: true,
            snapshot_every: None,
        }),
    }
}
