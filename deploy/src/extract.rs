//! `idmesh extract`: a tracker's output in, a version-2 trace of events
//! out (the sensor stage of `idmesh-extract`), and a summary on stderr.
//! Bad rows end the run with `FILE:LINE: reason` (exit status 1), unless
//! `--max-errors N` lets up to N of them be counted and reported.

use crate::cli::{ExtractArgs, ReportFormat, RosterChoice};
use anyhow::{bail, Context, Result};
use idmesh_extract::adapters::homography::Homography;
use idmesh_extract::adapters::jsonl::report_of;
use idmesh_extract::adapters::mot::{Ground, MotOptions, MotReader, Reads};
use idmesh_extract::adapters::ros2::bag::{BagOptions, BagRows};
use idmesh_extract::adapters::ros2::{MessageType, TopicOptions};
use idmesh_extract::adapters::Located;
use idmesh_extract::adapters::{eth_ucy, mot};
use idmesh_extract::{every_id, extract_jsonl, extract_rows, read_reports, Run, Tally};
use idmesh_extract::{ExtractorConfig, RosterPolicy, ScoreMapping};
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
    let input = open(args.input.as_deref().filter(|_| !from_stdin), &file)?;
    if args.format != ReportFormat::Mot && (args.reads.is_some() || !args.class_label.is_empty()) {
        bail!("--reads and --class-label are for --format mot (jsonl carries scores and reads in its detect lines)");
    }
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
    let run = Run::new(config(args), output, &sink, args.max_errors)?.with_red(args.red);
    let tally = match args.format {
        ReportFormat::Jsonl => {
            if args.roster == Some(RosterChoice::All) {
                bail!("--roster all reads the whole input first: for jsonl, give a header line with the tracks instead");
            }
            extract_jsonl(input, &file, run)?
        }
        ReportFormat::Mot => {
            let options = MotOptions {
                classes: args.class_label.iter().cloned().collect(),
                label: args.label.clone(),
                window: args.reorder_window,
                ..MotOptions::new(fps(args)?, ground(args)?)
            };
            let policy = match (args.roster, &args.input) {
                (Some(RosterChoice::FirstFrame), _) => RosterPolicy::FirstFrame,
                (None, _) if from_stdin => RosterPolicy::FirstFrame,
                (_, Some(path)) if !from_stdin => {
                    // A first pass for the ids alone: the roster of every
                    // id, in memory flat in the file's length.
                    let ids = mot::ids(open(Some(path), &file)?, &options)
                        .with_context(|| format!("{file}: cannot read"))?;
                    RosterPolicy::Declared(ids)
                }
                _ => bail!(
                    "--roster all reads the input twice: give a file, or --roster first-frame"
                ),
            };
            let reads = match &args.reads {
                Some(path) => {
                    let name = path.display().to_string();
                    Some(Reads::new(open(Some(path), &name)?, &name, options.window))
                }
                None => None,
            };
            let rows = MotReader::new(input, &file, options, reads)?;
            extract_rows(rows, &file, run, policy)?
        }
        ReportFormat::Rosbag2 => {
            let options = bag_options(args)?;
            let policy = match (args.roster, &args.input) {
                (Some(RosterChoice::FirstFrame), _) => RosterPolicy::FirstFrame,
                (None, _) if from_stdin => RosterPolicy::FirstFrame,
                (_, Some(path)) if !from_stdin => {
                    // A first pass for the ids alone, as for mot.
                    let rows = BagRows::new(open(Some(path), &file)?, &file, options.clone());
                    RosterPolicy::Declared(
                        rows.filter_map(|r| r.ok().map(|l| l.report.track))
                            .collect(),
                    )
                }
                _ => bail!(
                    "--roster all reads the input twice: give a file, or --roster first-frame"
                ),
            };
            extract_rows(BagRows::new(input, &file, options), &file, run, policy)?
        }
        format => {
            let text = read_all(input, &file)?;
            let fps = fps(args)?;
            let rows = match format {
                ReportFormat::Obsmat => {
                    eth_ucy::read(&text, &file, fps, eth_ucy::SceneFormat::Obsmat)?
                }
                _ => eth_ucy::read(&text, &file, fps, eth_ucy::SceneFormat::FourColumn)?,
            };
            let policy = match args.roster {
                Some(RosterChoice::FirstFrame) => RosterPolicy::FirstFrame,
                _ => RosterPolicy::Declared(every_id(&rows)),
            };
            extract_rows(rows, &file, run, policy)?
        }
    };
    summary(&file, &sink, &tally);
    Ok(())
}

/// Which topics of a bag, and their positions' scale.
fn bag_options(args: &ExtractArgs) -> Result<BagOptions> {
    let mut mapping = TopicOptions::new("/bag", MessageType::Detection2DArray);
    mapping.scale = args.scale.unwrap_or(1.0);
    if let Some(topic) = &args.topic {
        mapping.topic = topic.clone();
    }
    mapping.validate().map_err(anyhow::Error::msg)?;
    Ok(BagOptions {
        topic: args.topic.clone(),
        mapping,
    })
}

/// A file, or standard input (`None`), read line by line.
fn open(path: Option<&std::path::Path>, file: &str) -> Result<Box<dyn BufRead>> {
    Ok(match path {
        Some(path) => Box::new(BufReader::new(
            File::open(path).with_context(|| format!("{file}: cannot open"))?,
        )),
        None => Box::new(BufReader::new(std::io::stdin().lock())),
    })
}

fn fps(args: &ExtractArgs) -> Result<f64> {
    args.fps.context(
        "this --format needs --fps (frames per second; ETH obsmat 15, other ETH/UCY files 25)",
    )
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
/// reports read as a sensor reads its trace ([`read_reports`]: the same
/// reader, the same `max_errors`, the same messages) and extracted as the
/// sensors extract them (the same settings, the same code), written to a
/// temporary file that is removed when it is dropped, on every path out.
/// `None` when the sensors take events as they are. `max_errors`:
/// `--max-errors`, else the topology's sensor's.
pub fn twin_trace(
    topology: &crate::runtime::topology::Topology,
    trace: &std::path::Path,
    max_errors: Option<usize>,
) -> Result<Option<tempfile::NamedTempFile>> {
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
        if max_errors.is_some() {
            bail!(
                "--max-errors counts bad lines of reports: this topology's sensors take events \
                 as they are, which replay reads as a trace (its first bad line stops it)"
            );
        }
        return Ok(None);
    };
    let file = trace.display().to_string();
    let input = BufReader::new(File::open(trace).with_context(|| format!("{file}: cannot open"))?);
    let reports = read_reports(
        input,
        &file,
        &config,
        max_errors.unwrap_or(first.max_errors),
    )?;
    let out = tempfile::Builder::new()
        .prefix("idmesh-twin-")
        .suffix(".jsonl")
        .tempfile()
        .context("cannot create the twin's trace in the temporary folder")?;
    let sink = out.path().display().to_string();
    let mut run = Run::new(config, BufWriter::new(out.as_file()), &sink, 0)?;
    run.start_from(&reports.header)?;
    // The reader ran the extractor over them: each is taken.
    for (line, text) in reports.lines {
        if let Some(report) = report_of(&text) {
            run.row(&file, Ok(Located { line, report }))?;
        }
    }
    run.finish(&file)?;
    let mut err = std::io::stderr().lock();
    for message in &reports.skipped {
        let _ = writeln!(err, "{message}");
    }
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
    if count("observe") + count("identify") == 0 {
        let warning = "the trace holds no observation (no observe or identify line): replay \
                       answers the prior, k/n (one half without --red), for every track; give \
                       class scores or identity reads (detect lines, --reads, or a MOT class \
                       column with --class-label)";
        // On stderr, as every log line (RUST_LOG, default warn).
        tracing::warn!("{file}: {warning}");
    }
}
