//! `idmesh extract`: a tracker's output in, a version-2 trace of events
//! out (the sensor stage of `idmesh-extract`), and a summary on stderr.
//! Bad rows end the run with `FILE:LINE: reason` (exit status 1), unless
//! `--max-errors N` lets up to N of them be counted and reported.

use crate::cli::{ExtractArgs, ReportFormat, RosterChoice};
use anyhow::{bail, Context, Result};
use idmesh_extract::adapters::homography::Homography;
use idmesh_extract::adapters::mot::Ground;
use idmesh_extract::adapters::{eth_ucy, mot};
use idmesh_extract::pipeline::{extract_jsonl, extract_rows, Run, Tally};
use idmesh_extract::{ExtractorConfig, ScoreMapping};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Read, Write};

/// The extractor's settings from the command line.
pub fn config(args: &ExtractArgs) -> ExtractorConfig {
    ExtractorConfig {
        mix_distance: args.mix_distance,
        release_factor: args.release_factor,
        observe_distance: args.observe_distance,
        observe_interval: args.observe_interval,
        meeting_model: args.meetings.model(),
        scores: ScoreMapping {
            label: args.label.clone(),
            temperature: args.temperature,
        },
        move_interval: (!args.no_moves).then_some(args.move_interval),
        identities: args.identities,
        source: "idmesh extract".into(),
    }
}

pub fn run(args: &ExtractArgs) -> Result<()> {
    let from_stdin = args.input.as_ref().is_none_or(|p| p.as_os_str() == "-");
    let file = match &args.input {
        Some(path) if !from_stdin => path.display().to_string(),
        _ => "stdin".to_string(),
    };
    let input: Box<dyn BufRead> = if from_stdin {
        Box::new(BufReader::new(std::io::stdin().lock()))
    } else {
        Box::new(BufReader::new(
            File::open(&file).with_context(|| format!("{file}: cannot open"))?,
        ))
    };
    let (sink, output): (String, Box<dyn Write>) = match &args.out {
        Some(path) => (
            path.display().to_string(),
            Box::new(BufWriter::new(
                File::create(path).with_context(|| format!("{}: cannot create", path.display()))?,
            )),
        ),
        None => (
            "stdout".into(),
            Box::new(BufWriter::new(std::io::stdout().lock())),
        ),
    };
    let run = Run::new(config(args), output, &sink, args.max_errors)?;
    let tally = match args.format {
        ReportFormat::Jsonl => {
            if args.roster == Some(RosterChoice::All) {
                bail!("--roster all reads the whole input first: for jsonl, give a header line with the tracks instead");
            }
            extract_jsonl(input, &file, run)?
        }
        format => {
            let text = read_all(input, &file)?;
            let fps = args.fps.context(
                "this --format needs --fps (frames per second; ETH obsmat 15, other ETH/UCY files 25)",
            )?;
            let rows = match format {
                ReportFormat::Mot => mot::read(&text, &file, fps, ground(args)?)?,
                ReportFormat::Obsmat => {
                    eth_ucy::read(&text, &file, fps, eth_ucy::SceneFormat::Obsmat)?
                }
                _ => eth_ucy::read(&text, &file, fps, eth_ucy::SceneFormat::FourColumn)?,
            };
            let every_id = args.roster != Some(RosterChoice::FirstFrame);
            extract_rows(rows, &file, run, every_id)?
        }
    };
    summary(&file, &sink, &tally);
    Ok(())
}

fn ground(args: &ExtractArgs) -> Result<Ground> {
    match (&args.homography, args.scale) {
        (Some(path), _) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("{}: cannot read", path.display()))?;
            Ok(Ground::Homography(Homography::parse(
                &text,
                &path.display().to_string(),
            )?))
        }
        (None, Some(scale)) => Ok(Ground::Scale(scale)),
        (None, None) => {
            bail!("--format mot needs --scale (metres per pixel) or --homography H.txt")
        }
    }
}

fn read_all(mut input: Box<dyn BufRead>, file: &str) -> Result<String> {
    let mut text = String::new();
    input
        .read_to_string(&mut text)
        .with_context(|| format!("{file}: cannot read"))?;
    Ok(text)
}

/// With `idmesh replay --topology`: when the deployment's sensors extract
/// their events from a tracker's reports, the trace replay reads is those
/// reports, extracted as the sensors extract them (the same settings, the
/// same code): written to a file of its own, whose path this returns for
/// the caller to remove once replay is done. `None` when the sensors take
/// events as they are.
pub fn twin_trace(
    topology: &crate::runtime::topology::Topology,
    trace: &std::path::Path,
) -> Result<Option<std::path::PathBuf>> {
    let Some(first) = topology.sensors.first() else {
        return Ok(None);
    };
    if topology.sensors.iter().any(|s| s.extract != first.extract) {
        bail!(
            "the sensors' [sensor.extract] settings differ: every sensor extracts from the \
             one merged order, with one set of settings"
        );
    }
    let Some(config) = first.extract.clone() else {
        return Ok(None);
    };
    let file = trace.display().to_string();
    let input = BufReader::new(File::open(trace).with_context(|| format!("{file}: cannot open"))?);
    let out = std::env::temp_dir().join(format!("idmesh-twin-{}.jsonl", std::process::id()));
    let sink = out.display().to_string();
    let output =
        BufWriter::new(File::create(&out).with_context(|| format!("{sink}: cannot create"))?);
    let run = Run::new(config, output, &sink, 0)?;
    extract_jsonl(input, &file, run)?;
    Ok(Some(out))
}

/// Counts of reports, lines by kind and bad rows by reason, on stderr.
fn summary(file: &str, sink: &str, tally: &Tally) {
    let mut err = std::io::stderr().lock();
    for message in &tally.errors {
        let _ = writeln!(err, "{message}");
    }
    let count = |k: &str| tally.lines.get(k).copied().unwrap_or(0);
    let _ = writeln!(
        err,
        "{file} -> {sink}: {} reports, {} tracks; {} events ({} mix, {} observe, {} identify), {} move lines; {} rows rejected",
        tally.reports,
        tally.tracks,
        tally.events(),
        count("mix"),
        count("observe"),
        count("identify"),
        count("move"),
        tally.rejected_total()
    );
    for (reason, n) in &tally.rejected {
        let _ = writeln!(err, "  rejected, {reason}: {n}");
    }
}
