//! `idmesh simulate`: the scenario generator of the `sensor` crate behind a
//! command line, writing a trace file with a progress bar on stderr.

use crate::cli::{Motion, SimulateArgs};
use anyhow::{Context, Result};
use idmesh_sim::Scenario;
use idmesh_sim::{write_trace, write_tracker_output};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::fs::File;
use std::io::BufWriter;

/// The scenario the arguments describe.
pub fn scenario(args: &SimulateArgs) -> Result<Scenario> {
    let mut s = match args.model {
        Motion::Crowd => Scenario::crowd(),
        Motion::Waypoint => Scenario::waypoint(),
        Motion::Pedestrians => {
            let scene = args
                .scene
                .as_ref()
                .context("--model pedestrians needs --scene FILE")?;
            Scenario::pedestrians(scene)
        }
    };
    if let Some(n) = args.targets {
        s = s.targets(n);
    }
    if let Some(k) = args.red {
        s = s.red(k);
    }
    if let Some(d) = args.duration {
        s = s.duration(d);
    }
    if let Some(e) = args.events {
        s = s.events(e);
    }
    if let Some(d) = args.mix_distance {
        s = s.mix_distance(d);
    }
    if let Some(d) = args.observe_distance {
        s = s.observe_distance(d);
    }
    s = s.meetings(args.meetings.model());
    if let Some(t) = args.truth_interval {
        s = s.truth_interval(t);
    }
    if args.identities {
        s = s
            .identities(true)
            .identity_accuracy(args.identity_accuracy)
            .reveal_initial_identity(!args.hide_initial);
    }
    Ok(s.reveal_initial_red(!args.hide_initial)
        .tracker_reports(args.tracker_output.is_some())
        .seed(args.seed))
}

pub fn run(args: &SimulateArgs) -> Result<()> {
    let scenario = scenario(args)?;
    let bar = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{spinner} simulating [{bar:40}] {percent:>3}% ({eta})")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    let trace = scenario
        .generate_with_progress(&mut |done, total| {
            bar.set_length(total);
            bar.set_position(done);
        })
        .context("simulation failed")?;
    bar.finish_and_clear();
    let path = args.out.display().to_string();
    if let Some(folder) = args.out.parent().filter(|f| !f.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder)
            .with_context(|| format!("{}: cannot create the folder", folder.display()))?;
    }
    let file = File::create(&args.out).with_context(|| format!("{path}: cannot create"))?;
    write_trace(&trace, BufWriter::new(file), path.clone())?;
    if let Some(out) = &args.tracker_output {
        let path = out.display().to_string();
        let file = File::create(out).with_context(|| format!("{path}: cannot create"))?;
        if let Some(written) = write_tracker_output(&trace, BufWriter::new(file), path.clone()) {
            written?;
            eprintln!("{path}: what the simulated tracker reported");
        }
    }
    let stats = trace.stats();
    eprintln!(
        "{path}: {} tracks, {} mixes, {} observations ({:.0}% mixing)",
        trace.header.tracks,
        stats.mixes,
        stats.observations,
        100.0 * stats.mix_share
    );
    Ok(())
}
