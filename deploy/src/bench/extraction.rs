//! `idmesh bench --extraction`: what a sensor that extracts its events
//! from positions costs.
//!
//! - **Throughput**, in this process: `idmesh-extract`'s extractor fed
//!   frames of a synthetic crowd (people walking at 1.3 m/s through a
//!   field at 0.05 people per square metre, one report in ten with class
//!   scores), time per frame and reports per second, against a tracker's
//!   10 frames a second. Rounds of frames, the median with its interval.
//! - **Latency**, live: a deployment whose sensor extracts, fed over its
//!   ingest key by this process. Each round one pair of tracks meets (the
//!   first of the pair known red, the second blue; constant swap 0.5):
//!   the round sends the frame where they meet, then the next frame (a
//!   frame is sensed when the next one arrives: a live tracker's next
//!   frame comes a frame period later, which adds to these figures), and
//!   asks the coordinator until an answer shows the mix (the red track's
//!   probability leaves 1). Beside it, in the same rounds, a raw get
//!   round trip to the sensor and to the coordinator.

use super::ingest::{all_accepted, send};
use super::interval::{median, median_interval};
use super::latency::percentile;
use super::{write, BenchOptions, Deployment, Made};
use crate::runtime::query::ask;
use anyhow::{bail, Context, Result};
use idmesh_extract::{Extractor, ExtractorConfig, MeetingModel, Report, RosterPolicy};
use idmesh_protocol::trace::{Header, Line};
use idmesh_protocol::wire::query::MarginalsAnswer;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

/// The tracker's frame rate the throughput is held against.
const TARGET_FPS: f64 = 10.0;
/// Crowd sizes of the throughput figure.
const SIZES: [usize; 3] = [1_000, 10_000, 100_000];
/// Rounds of frames per size (the median and its interval are over them).
const ROUNDS: usize = 12;
/// Reports per round (frames × tracks), so a round takes about as long
/// whatever the size.
const REPORTS_PER_ROUND: usize = 200_000;
/// Pairs that meet in the latency figure (a round each), after a warm-up.
const MEETINGS: usize = 200;
const WARM_UP: usize = 20;
const LEADERS: usize = 2;
const TIMEOUT: Duration = Duration::from_secs(10);

/// One size's throughput.
struct Throughput {
    tracks: usize,
    frames_per_round: usize,
    /// Seconds per frame, one per round.
    per_frame: Vec<f64>,
    /// Events (mix + observe) out, per frame, over every round.
    events_per_frame: f64,
}

/// Frames of a synthetic crowd: `tracks` walkers in a square field at
/// 0.05 people/m², 1.3 m/s in random directions, bouncing off the edges.
struct Crowd {
    positions: Vec<(f64, f64)>,
    velocities: Vec<(f64, f64)>,
    side: f64,
    rng: ChaCha8Rng,
}

impl Crowd {
    fn new(tracks: usize, seed: u64) -> Crowd {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let side = (tracks as f64 / 0.05).sqrt();
        let positions = (0..tracks)
            .map(|_| (rng.gen_range(0.0..side), rng.gen_range(0.0..side)))
            .collect();
        let velocities = (0..tracks)
            .map(|_| {
                let angle: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
                (1.3 * angle.cos(), 1.3 * angle.sin())
            })
            .collect();
        Crowd {
            positions,
            velocities,
            side,
            rng,
        }
    }

    /// The reports of the frame at `time`, then one step of motion.
    fn frame(&mut self, time: f64) -> Vec<Report> {
        let mut reports = Vec::with_capacity(self.positions.len());
        for (track, &(x, y)) in self.positions.iter().enumerate() {
            let mut report = Report::at(time, track as u32, x, y);
            if self.rng.gen_range(0..10) == 0 {
                let s: f64 = self.rng.gen_range(0.05..0.95);
                report.scores = Some(BTreeMap::from([
                    ("red".to_string(), s),
                    ("blue".to_string(), 1.0 - s),
                ]));
            }
            reports.push(report);
        }
        let dt = 1.0 / TARGET_FPS;
        for (p, v) in self.positions.iter_mut().zip(&mut self.velocities) {
            p.0 += v.0 * dt;
            p.1 += v.1 * dt;
            if !(0.0..self.side).contains(&p.0) {
                v.0 = -v.0;
                p.0 = p.0.clamp(0.0, self.side);
            }
            if !(0.0..self.side).contains(&p.1) {
                v.1 = -v.1;
                p.1 = p.1.clamp(0.0, self.side);
            }
        }
        reports
    }
}

fn throughput(tracks: usize) -> Result<Throughput> {
    let frames = (REPORTS_PER_ROUND / tracks).max(3);
    let mut crowd = Crowd::new(tracks, 7);
    let config = ExtractorConfig {
        move_interval: None,
        ..ExtractorConfig::default()
    };
    let mut extractor =
        Extractor::new(config, RosterPolicy::Declared((0..tracks as u32).collect()))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut out: Vec<Line> = Vec::new();
    let (mut per_frame, mut events) = (Vec::with_capacity(ROUNDS), 0usize);
    let mut frame = 0u64;
    // One round of warm-up, not timed.
    for round in 0..=ROUNDS {
        // The frames are made before the clock starts: only the
        // extractor is timed.
        let batch: Vec<Vec<Report>> = (0..frames)
            .map(|_| {
                frame += 1;
                crowd.frame(frame as f64 / TARGET_FPS)
            })
            .collect();
        let started = Instant::now();
        for reports in batch {
            for report in reports {
                extractor
                    .push(report, &mut out)
                    .context("a synthetic report")?;
            }
        }
        let seconds = started.elapsed().as_secs_f64();
        if round > 0 {
            per_frame.push(seconds / frames as f64);
            events += out
                .iter()
                .filter(|l| matches!(l, Line::Mix(_) | Line::Observe(_)))
                .count();
        }
        out.clear();
    }
    Ok(Throughput {
        tracks,
        frames_per_round: frames,
        per_frame,
        events_per_frame: events as f64 / (ROUNDS * frames) as f64,
    })
}

/// What the latency rounds measured.
struct Latency {
    /// From sending the frame where a pair meets to the first answer with
    /// its mix.
    to_answer: Vec<Duration>,
    /// From sending that frame to the acknowledgement of the next one:
    /// the two ingest round trips.
    ingested: Vec<Duration>,
    /// A raw get to the sensor's ping, and to the coordinator's.
    ping_sensor: Vec<Duration>,
    ping_coordinator: Vec<Duration>,
    /// Answers asked for before the one that showed the mix, in all.
    polls: usize,
}

/// The header of the latency stream: `2 × pairs` tracks, the even ones
/// known red.
fn latency_header(pairs: usize) -> Header {
    let mut header = Header::new_v2(2 * pairs);
    header.red = Some(pairs);
    header.initial_red = Some((0..pairs as u32).map(|p| 2 * p).collect());
    header.source = Some("idmesh bench --extraction".into());
    header
}

/// Frame `f` of the latency stream as detect lines: pair p stands at
/// (10 p, 0) and (10 p + 5, 0), except in frame 2p + 1, where its second
/// track stands 0.5 m from its first: one meeting, sensed when frame
/// 2p + 2 arrives.
fn latency_frame(pairs: usize, f: usize) -> String {
    let time = f as f64 / TARGET_FPS;
    let mut lines = Vec::with_capacity(2 * pairs);
    for p in 0..pairs {
        let x = 10.0 * p as f64;
        let gap = if f == 2 * p + 1 { 0.5 } else { 5.0 };
        for (track, x) in [(2 * p, x), (2 * p + 1, x + gap)] {
            lines.push(format!(
                r#"{{"kind":"detect","time":{time},"track":{track},"x":{x},"y":0}}"#
            ));
        }
    }
    lines.join("\n")
}

async fn latency(deployment: &Deployment, pairs: usize) -> Result<Latency> {
    let keys = deployment.keys();
    let sensor = &deployment.topology.sensor().name;
    let ingest = keys.sensor_ingest(sensor);
    let ping_sensor = keys.ping("sensor", sensor);
    let ping_coordinator = keys.ping("coordinator", &deployment.topology.coordinator.name);
    let marginals = keys.query_marginals();
    deployment
        .wait_for(&ping_sensor, 1, TIMEOUT)
        .await
        .context("the sensor did not come up")?;
    let mut l = Latency {
        to_answer: Vec::with_capacity(pairs),
        ingested: Vec::with_capacity(pairs),
        ping_sensor: Vec::with_capacity(pairs),
        ping_coordinator: Vec::with_capacity(pairs),
        polls: 0,
    };
    // A producer's counter numbers its lines: a request's is the count of
    // lines it sent before.
    let mut counter = 0u64;
    let mut frame = |f: usize| {
        let first = counter;
        counter += 2 * pairs as u64;
        (first, latency_frame(pairs, f))
    };
    let (c, first) = frame(0);
    all_accepted(
        "bench",
        &send(deployment, &ingest, "bench", c, &first).await?,
        2 * pairs,
    )?;
    for p in 0..pairs {
        let (c1, meeting) = frame(2 * p + 1);
        let (c2, next) = frame(2 * p + 2);
        let sent = Instant::now();
        all_accepted(
            "bench",
            &send(deployment, &ingest, "bench", c1, &meeting).await?,
            2 * pairs,
        )?;
        all_accepted(
            "bench",
            &send(deployment, &ingest, "bench", c2, &next).await?,
            2 * pairs,
        )?;
        let ingested = sent.elapsed();
        let red = 2 * p;
        let mut polls = 0;
        loop {
            let answer: MarginalsAnswer =
                serde_json::from_slice(&ask(&deployment.session, &marginals, TIMEOUT).await?)?;
            if answer.p_red.get(red).is_some_and(|&q| q < 0.999) {
                break;
            }
            polls += 1;
            if sent.elapsed() > TIMEOUT {
                bail!("the mix of pair {p} did not show in {TIMEOUT:?}");
            }
        }
        let to_answer = sent.elapsed();
        let before = Instant::now();
        deployment.ping(&ping_sensor, 1).await?;
        let raw_sensor = before.elapsed();
        let before = Instant::now();
        deployment.ping(&ping_coordinator, 1).await?;
        let raw_coordinator = before.elapsed();
        if p >= WARM_UP {
            l.to_answer.push(to_answer);
            l.ingested.push(ingested);
            l.ping_sensor.push(raw_sensor);
            l.ping_coordinator.push(raw_coordinator);
            l.polls += polls;
        }
    }
    Ok(l)
}

fn ms(d: Duration) -> String {
    format!("{:.2}", d.as_secs_f64() * 1e3)
}

/// Runs both figures and writes the page to `--out` (printed too).
pub fn run(runtime: &tokio::runtime::Runtime, options: &BenchOptions) -> Result<()> {
    let started = Instant::now();
    let mut report = String::new();
    writeln!(
        report,
        "## Throughput: events from positions, in one sensor\n\n\
         `idmesh-extract`'s extractor in this process, fed frames of a synthetic crowd \
         (0.05 people/m², 1.3 m/s, one report in ten with class scores; default settings: \
         mix within 1 m, observe beyond 3.5 m at most every 3 s). {ROUNDS} rounds of about \
         {REPORTS_PER_ROUND} reports per size after one round of warm-up; the median time \
         per frame with its interval ({:.0}% confidence, distribution-free). A tracker at \
         {TARGET_FPS} frames a second needs a frame in under {:.0} ms.\n",
        100.0 * super::interval::CONFIDENCE,
        1e3 / TARGET_FPS
    )?;
    writeln!(
        report,
        "| tracks | frames a round | ms a frame (median) | interval | reports/s | events/s | frames/s ÷ {TARGET_FPS} |"
    )?;
    writeln!(report, "|---|---|---|---|---|---|---|")?;
    for tracks in SIZES {
        eprintln!("bench: extracting frames of {tracks} tracks");
        let t = throughput(tracks)?;
        let median = median(&t.per_frame);
        let interval = median_interval(&t.per_frame).map_or("—".into(), |(lo, hi, _)| {
            format!("[{:.2}, {:.2}]", lo * 1e3, hi * 1e3)
        });
        writeln!(
            report,
            "| {} | {} | {:.2} | {interval} | {:.2} M | {:.0} | {:.1}× |",
            t.tracks,
            t.frames_per_round,
            median * 1e3,
            t.tracks as f64 / median / 1e6,
            t.events_per_frame / median,
            1.0 / median / TARGET_FPS,
        )?;
    }

    let dir = &options.dir;
    std::fs::create_dir_all(dir)?;
    let pairs = WARM_UP + MEETINGS;
    let header = dir.join("extraction-header.jsonl");
    std::fs::write(
        &header,
        serde_json::to_string(&Line::Header(latency_header(pairs)))? + "\n",
    )?;
    let extract = ExtractorConfig {
        meeting_model: MeetingModel::Constant(0.5),
        ..ExtractorConfig::default()
    };
    eprintln!("bench: {MEETINGS} meetings through a live extracting sensor, {LEADERS} leaders");
    let deployment = runtime.block_on(Deployment::start_extracting(
        options, &header, LEADERS, extract,
    ))?;
    let measured = runtime.block_on(latency(&deployment, pairs));
    runtime.block_on(deployment.close());
    let l = measured?;
    writeln!(
        report,
        "\n## Latency: from a position to the answer with its mix\n\n\
         A live deployment ({LEADERS} leaders, the factored belief at the default settings; \
         the sensor extracts with the default settings) fed by this process over the \
         sensor's ingest key, {} tracks. Each of {MEETINGS} rounds (after {WARM_UP} of \
         warm-up) sends the frame where one pair meets and the frame after it (the extractor \
         senses a frame when the next one arrives, so a live tracker adds one frame period, \
         {:.0} ms at {TARGET_FPS} frames a second, to the first column), then asks the \
         coordinator for the marginals until the pair's red track has left 1. In the same \
         rounds: a raw get round trip to the sensor and to the coordinator.\n",
        2 * pairs,
        1e3 / TARGET_FPS
    )?;
    writeln!(
        report,
        "| ms | position → answer with its mix | the two frames acknowledged | raw round trip, sensor | raw round trip, coordinator |"
    )?;
    writeln!(report, "|---|---|---|---|---|")?;
    for (name, p) in [("p50", 0.5), ("p99", 0.99)] {
        writeln!(
            report,
            "| {name} | {} | {} | {} | {} |",
            ms(percentile(&l.to_answer, p)),
            ms(percentile(&l.ingested, p)),
            ms(percentile(&l.ping_sensor, p)),
            ms(percentile(&l.ping_coordinator, p)),
        )?;
    }
    writeln!(
        report,
        "\nAnswers asked for that did not show the mix yet: {:.2} a round on average.",
        l.polls as f64 / l.to_answer.len().max(1) as f64
    )?;
    print!("{report}");
    if let Some(out) = &options.out {
        let made = Made::since(started);
        write(out, &page(out, &report, &made))?;
    }
    Ok(())
}

fn page(out: &Path, report: &str, made: &Made) -> String {
    let args = format!("bench --extraction --out {}", out.display());
    super::page_of("extracting events from positions", &args, report, made)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_latency_round_makes_one_meeting_of_its_pair() {
        let pairs = 5;
        let config = ExtractorConfig {
            move_interval: None,
            ..ExtractorConfig::default()
        };
        let mut extractor = Extractor::new(config, RosterPolicy::Declared((0..10).collect()))
            .unwrap()
            .with_prior(&latency_header(pairs));
        let mut out = Vec::new();
        for f in 0..=2 * pairs {
            for line in latency_frame(pairs, f).lines() {
                let Line::Detect(d) = serde_json::from_str(line).unwrap() else {
                    panic!("not a detect line: {line}");
                };
                extractor.push(d.into(), &mut out).unwrap();
            }
        }
        let mixes: Vec<(u32, u32)> = out
            .iter()
            .filter_map(|l| match l {
                Line::Mix(m) => Some((m.a, m.b)),
                _ => None,
            })
            .collect();
        assert_eq!(
            mixes,
            (0..pairs as u32)
                .map(|p| (2 * p, 2 * p + 1))
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn the_synthetic_crowd_meets_and_is_seen() {
        let t = throughput(1_000).unwrap();
        assert_eq!(t.per_frame.len(), ROUNDS);
        assert!(t.events_per_frame > 0.5, "{}", t.events_per_frame);
    }
}
