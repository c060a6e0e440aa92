//! Live ingestion against the physical floor: one producer (the bench's own
//! peer session, one hop from the sensor) feeds a live sensor's ingest key
//! and waits for each acknowledgement before the next request, as a
//! producer that keeps nothing unacknowledged in flight does. Throughput:
//! events acknowledged per second, by lines per request. Latency: a
//! one-line ingest request interleaved with a raw get to the sensor's ping
//! queryable, in the same run, so both see the same noise.

use super::latency::percentile;
use super::{BenchOptions, Deployment};
use anyhow::{anyhow, bail, Context, Result};
use idmesh_protocol::wire::producer_to_sensor::IngestAck;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(10);
const WARM_UP: usize = 50;
/// Lines per request the throughput is measured at.
const BATCHES: [usize; 3] = [1, 100, 1000];
/// At one line a request, the events sent (a round trip each).
const SINGLE_LINES: usize = 5000;

pub struct Ingestion {
    /// (lines per request, events acknowledged, how long it took).
    pub throughput: Vec<(usize, u64, Duration)>,
    pub ingest_one: Vec<Duration>,
    pub ping: Vec<Duration>,
}

/// A trace of `trace`'s header alone, beside it: a live sensor's field.
pub fn header_only(trace: &Path, dir: &Path) -> Result<PathBuf> {
    let text = std::fs::read_to_string(trace)
        .with_context(|| format!("cannot read {}", trace.display()))?;
    let header = text.lines().next().context("an empty trace")?;
    let path = dir.join("header-only.jsonl");
    std::fs::write(&path, format!("{header}\n"))?;
    Ok(path)
}

/// The events of `trace`, as the lines a producer sends.
fn events(trace: &Path) -> Result<Vec<String>> {
    let text = std::fs::read_to_string(trace)?;
    Ok(text
        .lines()
        .filter(|l| {
            ["mix", "observe", "move", "identify"]
                .iter()
                .any(|k| l.contains(&format!("\"kind\":\"{k}\"")))
        })
        .map(str::to_owned)
        .collect())
}

pub async fn measure(deployment: &Deployment, trace: &Path, queries: usize) -> Result<Ingestion> {
    let keys = deployment.keys();
    let sensor = &deployment.topology.sensor().name;
    let ping = keys.ping("sensor", sensor);
    let ingest = keys.sensor_ingest(sensor);
    deployment
        .wait_for(&ping, 1, TIMEOUT)
        .await
        .context("the sensor did not come up")?;
    let lines = events(trace)?;
    let mut figures = Ingestion {
        throughput: Vec::new(),
        ingest_one: Vec::with_capacity(queries),
        ping: Vec::with_capacity(queries),
    };
    // The first rounds (the sensor may still wait for its leaders) are a
    // warm-up, not timed.
    let started = Instant::now();
    for round in 0..WARM_UP + queries {
        let counter = round as u64;
        let line = &lines[round % lines.len()];
        let before = Instant::now();
        send(deployment, &ingest, "latency", counter, line).await?;
        let one = before.elapsed();
        let before = Instant::now();
        deployment.ping(&ping, 1).await?;
        let raw = before.elapsed();
        if round >= WARM_UP {
            figures.ingest_one.push(one);
            figures.ping.push(raw);
        }
        if started.elapsed() > Duration::from_secs(600) {
            bail!("latency rounds took over 10 minutes");
        }
    }
    for batch in BATCHES {
        let producer = format!("throughput-{batch}");
        let sent = if batch == 1 {
            &lines[..SINGLE_LINES.min(lines.len())]
        } else {
            &lines[..]
        };
        let started = Instant::now();
        let mut accepted = 0u64;
        for (i, chunk) in sent.chunks(batch).enumerate() {
            let ack = send(
                deployment,
                &ingest,
                &producer,
                (i * batch) as u64,
                &chunk.join("\n"),
            )
            .await?;
            all_accepted(&producer, &ack, chunk.len())?;
            accepted += ack.accepted.len() as u64;
        }
        figures
            .throughput
            .push((batch, accepted, started.elapsed()));
    }
    Ok(figures)
}

/// Every one of the `lines` a request of `producer`'s carried was taken.
pub(super) fn all_accepted(producer: &str, ack: &IngestAck, lines: usize) -> Result<()> {
    if ack.accepted.len() != lines {
        bail!(
            "{producer}: {} of {lines} lines accepted: {:?}",
            ack.accepted.len(),
            ack.errors.first()
        );
    }
    Ok(())
}

/// One ingest request, until acknowledged.
pub(super) async fn send(
    deployment: &Deployment,
    key: &str,
    producer: &str,
    counter: u64,
    payload: &str,
) -> Result<IngestAck> {
    put(
        &deployment.session,
        key,
        &format!("producer={producer};counter={counter}"),
        payload.to_string(),
    )
    .await
}

/// One request to an ingest key with these `parameters`: its
/// acknowledgement, or why there is none.
pub(super) async fn put(
    session: &zenoh::Session,
    key: &str,
    parameters: &str,
    payload: String,
) -> Result<IngestAck> {
    let replies = session
        .get(format!("{key}?{parameters}"))
        .payload(payload)
        .timeout(TIMEOUT)
        .await
        .map_err(|e| anyhow!("ingest: {e}"))?;
    let reply = replies
        .recv_async()
        .await
        .map_err(|_| anyhow!("ingest: no reply within {TIMEOUT:?}"))?;
    match reply.result() {
        Ok(sample) => Ok(serde_json::from_slice(&sample.payload().to_bytes())?),
        Err(e) => bail!(
            "ingest refused: {}",
            e.payload().try_to_string().unwrap_or_default()
        ),
    }
}

pub fn report(f: &Ingestion, options: &BenchOptions, out: &mut String) -> Result<()> {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    writeln!(
        out,
        "Crowd of {} targets ({} red), {} s simulated, fed by one producer (a peer session one hop from the sensor, each request waiting for its acknowledgement) to a live sensor streaming to 1 leader; every process on this machine's loopback.\n",
        options.targets, options.red, options.duration
    )?;
    writeln!(out, "### Ingestion throughput, one producer, one sensor\n")?;
    writeln!(
        out,
        "| lines per request | events acknowledged | seconds | events/s |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|")?;
    for &(batch, events, took) in &f.throughput {
        writeln!(
            out,
            "| {batch} | {events} | {:.2} | {:.0} |",
            took.as_secs_f64(),
            events as f64 / took.as_secs_f64()
        )?;
    }
    writeln!(
        out,
        "\n### One-line ingest round trip against a raw get to the sensor ({} of each, interleaved)\n",
        f.ping.len()
    )?;
    writeln!(out, "| get | p50 ms | p99 ms | p50 / raw | p99 / raw |")?;
    writeln!(out, "|---|---:|---:|---:|---:|")?;
    for (name, samples) in [
        ("ingest, one line, acknowledged", &f.ingest_one),
        ("raw get to the sensor", &f.ping),
    ] {
        let (p50, p99) = (percentile(samples, 0.5), percentile(samples, 0.99));
        writeln!(
            out,
            "| {name} | {:.3} | {:.3} | {:.1}× | {:.1}× |",
            ms(p50),
            ms(p99),
            ms(p50) / ms(percentile(&f.ping, 0.5)),
            ms(p99) / ms(percentile(&f.ping, 0.99)),
        )?;
    }
    writeln!(out)?;
    Ok(())
}
