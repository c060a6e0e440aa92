//! Several live sensors fed at once. The crowd's events are
//! split by region — a track's events go to the sensor nearest its last
//! position, as one camera per region would see them — and each sensor is
//! fed by its own producer (`camera-<s>`, its own counters, 100 lines a
//! request, each request saying the time it reached), all concurrently.
//! Throughput: events acknowledged per second, and events per second until
//! an answer includes them all (every sensor's intake merged and routed).
//! Latency: one event put on sensor 0 while every other sensor's producer
//! says every few milliseconds how far its time is (a camera with nothing
//! to report still says so), to the first marginals answer whose
//! watermark includes the event; against a raw get to sensor 0 in the
//! same run.

use super::ingest::{all_accepted, put};
use super::latency::percentile;
use super::Deployment;
use crate::runtime::launch::field_corners;
use crate::runtime::query::ask;
use anyhow::{anyhow, bail, Result};
use idmesh_protocol::wire::query::MarginalsAnswer;
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(10);
/// Lines per request.
const BATCH: usize = 100;
/// How often an idle producer says how far its time is.
const TICK: Duration = Duration::from_millis(5);

pub struct SensorsFigures {
    pub sensors: usize,
    pub events: u64,
    /// Until every producer had every line acknowledged.
    pub acknowledged: Duration,
    /// Until a marginals answer included every event.
    pub answered: Duration,
    /// A put on sensor 0 to the first answer that includes it.
    pub to_answer: Vec<Duration>,
    /// A raw get to sensor 0, interleaved.
    pub raw: Vec<Duration>,
}

/// A sensor's events: each line with its time.
type Timed = Vec<(f64, String)>;

/// Each sensor's lines, by region, and the crowd's last time.
fn split(trace: &Path, sensors: usize) -> Result<(Vec<Timed>, f64)> {
    // Each sensor sees the cell of a grid over the field.
    let places = idmesh_placement::grid_places(field_corners(trace)?, sensors);
    let text = std::fs::read_to_string(trace)?;
    let mut at: Vec<Option<(f64, f64)>> = Vec::new();
    let mut given = vec![Vec::new(); sensors];
    let mut last_time = 0.0f64;
    for line in text.lines() {
        let Ok(event) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        let track = match event["kind"].as_str() {
            Some("mix") => event["a"].as_u64(),
            Some("observe" | "move" | "identify") => event["track"].as_u64(),
            _ => continue,
        }
        .ok_or_else(|| anyhow!("an event without its track: {line}"))? as usize;
        if at.len() <= track {
            at.resize(track + 1, None);
        }
        if event["kind"] == "move" {
            at[track] = event["x"].as_f64().zip(event["y"].as_f64());
        }
        let s = match at[track] {
            None => track % sensors,
            Some((x, y)) => (0..sensors)
                .min_by(|&a, &b| {
                    let d = |p: (f64, f64)| (p.0 - x).powi(2) + (p.1 - y).powi(2);
                    d(places[a]).total_cmp(&d(places[b]))
                })
                .unwrap_or(0),
        };
        let time = event["time"].as_f64().unwrap_or(last_time);
        last_time = time;
        given[s].push((time, line.to_string()));
    }
    Ok((given, last_time))
}

/// The events the marginals answer includes now.
async fn answered(deployment: &Deployment) -> Result<u64> {
    let body = ask(
        &deployment.session,
        &deployment.keys().query_marginals(),
        TIMEOUT,
    )
    .await?;
    let answer: MarginalsAnswer = serde_json::from_slice(&body)?;
    Ok(answer.watermark.values().sum())
}

/// Waits for every sensor to answer a ping and the deployment to answer
/// a marginals query.
async fn wait_until_up(deployment: &Deployment, names: &[String]) -> Result<()> {
    let keys = deployment.keys();
    let started = Instant::now();
    for name in names {
        while let Err(e) = deployment.ping(&keys.ping("sensor", name), 1).await {
            if started.elapsed() > TIMEOUT {
                return Err(e.context(format!("{name} did not come up")));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }
    while answered(deployment).await.is_err() {
        if started.elapsed() > Duration::from_secs(60) {
            bail!("no answer from the deployment within a minute");
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    Ok(())
}

/// Puts each sensor's lines on its ingest key, [`BATCH`] at a time, one
/// producer per sensor, all at once; returns when every line was
/// acknowledged. With several sensors each producer also says how far its
/// time is, and at the end that its clock goes on past the crowd.
async fn feed(
    deployment: &Deployment,
    names: &[String],
    given: Vec<Timed>,
    meshed: bool,
    last_time: f64,
) -> Result<()> {
    let keys = deployment.keys();
    let mut feeds: Vec<tokio::task::JoinHandle<Result<()>>> = Vec::new();
    for (s, lines) in given.into_iter().enumerate() {
        let session = deployment.session.clone();
        let key = keys.sensor_ingest(&names[s]);
        feeds.push(tokio::spawn(async move {
            let producer = format!("camera-{s}");
            let mut counter = 0usize;
            for chunk in lines.chunks(BATCH) {
                let mut parameters = format!("producer={producer};counter={counter}");
                if meshed {
                    let time = chunk.last().map_or(0.0, |(t, _)| *t);
                    parameters.push_str(&format!(";time={time}"));
                }
                let payload = chunk
                    .iter()
                    .map(|(_, l)| l.as_str())
                    .collect::<Vec<_>>()
                    .join("\n");
                let ack = put(&session, &key, &parameters, payload).await?;
                all_accepted(&producer, &ack, chunk.len())?;
                counter += chunk.len();
            }
            if meshed {
                // Its camera's clock goes on past the crowd's last event.
                let parameters = format!("producer={producer};time={}", last_time + 0.5);
                put(&session, &key, &parameters, String::new()).await?;
            }
            Ok(())
        }));
    }
    for feed in feeds {
        feed.await??;
    }
    Ok(())
}

pub async fn measure(
    deployment: &Deployment,
    trace: &Path,
    sensors: usize,
    samples: usize,
) -> Result<SensorsFigures> {
    let keys = deployment.keys();
    let names: Vec<String> = (0..sensors).map(|s| format!("sensor-{s}")).collect();
    wait_until_up(deployment, &names).await?;
    let meshed = sensors > 1;
    let (given, last_time) = split(trace, sensors)?;
    let events: u64 = given.iter().map(|g| g.len() as u64).sum();
    let started = Instant::now();
    feed(deployment, &names, given, meshed, last_time).await?;
    let acknowledged = started.elapsed();
    while answered(deployment).await? < events {
        if started.elapsed() > Duration::from_secs(600) {
            bail!("the events were not all answered within 10 minutes");
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    let answered_all = started.elapsed();
    // Latency: every producer says how far its time is, every few ms;
    // one event at a time is put on sensor 0 and answered.
    let clock = Instant::now();
    let time_now = move || last_time + 1.0 + clock.elapsed().as_secs_f64();
    let ticking = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let mut tickers = Vec::new();
    if meshed {
        // Sensor 0's own time moves with the probe's events.
        for name in &names[1..] {
            let session = deployment.session.clone();
            let key = keys.sensor_ingest(name);
            let ticking = ticking.clone();
            tickers.push(tokio::spawn(async move {
                while ticking.load(std::sync::atomic::Ordering::Relaxed) {
                    let parameters = format!("producer=clock;time={}", time_now());
                    let _ = put(&session, &key, &parameters, String::new()).await;
                    tokio::time::sleep(TICK).await;
                }
            }));
        }
    }
    let probe = keys.sensor_ingest(&names[0]);
    let ping = keys.ping("sensor", &names[0]);
    let mut to_answer = Vec::with_capacity(samples);
    let mut raw = Vec::with_capacity(samples);
    let mut included = events;
    for i in 0..samples {
        let time = time_now();
        let line = format!(r#"{{"kind":"observe","time":{time},"track":0,"red":0.6,"blue":0.4}}"#);
        let mut parameters = format!("producer=probe;counter={i}");
        if meshed {
            parameters.push_str(&format!(";time={time}"));
        }
        let before = Instant::now();
        let ack = put(&deployment.session, &probe, &parameters, line).await?;
        if ack.accepted.len() != 1 {
            bail!("the probe's event {i} was refused: {:?}", ack.errors);
        }
        included += 1;
        while answered(deployment).await? < included {
            if before.elapsed() > TIMEOUT {
                bail!("event {i} of the probe was not answered within {TIMEOUT:?}");
            }
        }
        to_answer.push(before.elapsed());
        let before = Instant::now();
        deployment.ping(&ping, 1).await?;
        raw.push(before.elapsed());
    }
    ticking.store(false, std::sync::atomic::Ordering::Relaxed);
    for ticker in tickers {
        let _ = ticker.await;
    }
    Ok(SensorsFigures {
        sensors,
        events,
        acknowledged,
        answered: answered_all,
        to_answer,
        raw,
    })
}

pub fn report(figures: &[SensorsFigures], out: &mut String) -> Result<()> {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    writeln!(
        out,
        "### Several sensors, each fed by its own producer ({BATCH} lines a request), all at once\n"
    )?;
    writeln!(
        out,
        "| sensors | events | acknowledged, s | events/s acknowledged | all in an answer, s | events/s answered |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|")?;
    for f in figures {
        writeln!(
            out,
            "| {} | {} | {:.2} | {:.0} | {:.2} | {:.0} |",
            f.sensors,
            f.events,
            f.acknowledged.as_secs_f64(),
            f.events as f64 / f.acknowledged.as_secs_f64(),
            f.answered.as_secs_f64(),
            f.events as f64 / f.answered.as_secs_f64(),
        )?;
    }
    writeln!(
        out,
        "\n### From a producer's put to the first answer that includes the event\n"
    )?;
    writeln!(
        out,
        "| sensors | samples | p50 ms | p99 ms | raw get p50 ms | raw get p99 ms | p50 / raw | p99 / raw |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    for f in figures {
        let (p50, p99) = (
            percentile(&f.to_answer, 0.5),
            percentile(&f.to_answer, 0.99),
        );
        let (r50, r99) = (percentile(&f.raw, 0.5), percentile(&f.raw, 0.99));
        writeln!(
            out,
            "| {} | {} | {:.2} | {:.2} | {:.3} | {:.3} | {:.0}× | {:.0}× |",
            f.sensors,
            f.to_answer.len(),
            ms(p50),
            ms(p99),
            ms(r50),
            ms(r99),
            ms(p50) / ms(r50),
            ms(p99) / ms(r99),
        )?;
    }
    writeln!(out)?;
    Ok(())
}
