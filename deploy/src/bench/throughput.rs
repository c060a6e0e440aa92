//! Events per second through a deployment: the sensor streams as fast as
//! the mesh takes it, and the bench asks the coordinator for the marginals
//! every few milliseconds. The stream starts after the last answer that saw
//! no event (the question was sent before the first event: the clock starts
//! then) and is through when an answer covers all of it: what a user
//! watching the answers would see, leaders' backlog included. If the bench
//! never saw the stream at zero, it counts from the first answer it got.

use super::Deployment;
use crate::runtime::query::ask;
use anyhow::{bail, Result};
use idmesh_protocol::wire::coordinator_to_leader::LeaderStats;
use idmesh_protocol::wire::query::{MarginalsAnswer, StatsAnswer};
use std::fmt::Write as _;
use std::time::{Duration, Instant};

const POLL: Duration = Duration::from_millis(10);
const START_PATIENCE: Duration = Duration::from_secs(120);
const ASK_TIMEOUT: Duration = Duration::from_secs(10);

pub struct Stream {
    pub leaders: usize,
    /// Events in the trace (the final watermark).
    pub events: u64,
    /// Events already in when the first moving answer came.
    pub first_seen: u64,
    pub seconds: f64,
    pub queries: usize,
    pub stats: Vec<LeaderStats>,
}

impl Stream {
    pub fn events_per_second(&self) -> f64 {
        (self.events - self.first_seen) as f64 / self.seconds
    }
}

pub async fn measure(deployment: &Deployment) -> Result<Stream> {
    let keys = deployment.keys();
    let key = keys.query_marginals();
    let started = Instant::now();
    let mut first: Option<(Instant, u64)> = None;
    let mut last_zero: Option<Instant> = None;
    let mut queries = 0;
    let mut last_error = String::new();
    loop {
        let asked = Instant::now();
        match ask(&deployment.session, &key, ASK_TIMEOUT).await {
            Ok(body) => {
                queries += 1;
                let answer: MarginalsAnswer = serde_json::from_slice(&body)?;
                let events: u64 = answer.watermark.values().sum();
                if events == 0 {
                    last_zero = Some(asked);
                } else if first.is_none() {
                    first = Some((
                        last_zero.unwrap_or(asked),
                        if last_zero.is_some() { 0 } else { events },
                    ));
                }
                if answer.finished {
                    let Some((since, first_seen)) = first.filter(|f| f.1 < events) else {
                        bail!("the stream was over before the bench could time it: make it longer");
                    };
                    let stats = stats(deployment).await?;
                    return Ok(Stream {
                        leaders: deployment.leaders,
                        events,
                        first_seen,
                        seconds: since.elapsed().as_secs_f64(),
                        queries,
                        stats,
                    });
                }
            }
            Err(e)
                if first.is_none() && last_zero.is_none() && started.elapsed() < START_PATIENCE =>
            {
                last_error = e.to_string();
            }
            Err(e) => bail!("marginals query failed during the stream: {e}"),
        }
        if first.is_none() && last_zero.is_none() && started.elapsed() > START_PATIENCE {
            bail!("the deployment did not start streaming within {START_PATIENCE:?}: {last_error}");
        }
        tokio::time::sleep(POLL).await;
    }
}

/// Waits until the coordinator answers with the stream moving.
pub async fn first_moving_answer(deployment: &Deployment) -> Result<()> {
    let key = deployment.keys().query_marginals();
    let started = Instant::now();
    loop {
        let last = match ask(&deployment.session, &key, ASK_TIMEOUT).await {
            Ok(body) => {
                let answer: MarginalsAnswer = serde_json::from_slice(&body)?;
                if answer.watermark.values().sum::<u64>() > 0 {
                    return Ok(());
                }
                "the stream has not started".to_string()
            }
            Err(e) => e.to_string(),
        };
        if started.elapsed() > START_PATIENCE {
            bail!("the deployment did not start streaming within {START_PATIENCE:?}: {last}");
        }
        tokio::time::sleep(POLL).await;
    }
}

async fn stats(deployment: &Deployment) -> Result<Vec<LeaderStats>> {
    let body = ask(
        &deployment.session,
        &deployment.keys().query_stats(),
        ASK_TIMEOUT,
    )
    .await?;
    let answer: StatsAnswer = serde_json::from_slice(&body)?;
    Ok(answer.leaders)
}

pub fn report(streams: &[Stream], out: &mut String) -> Result<()> {
    writeln!(out, "### Throughput\n")?;
    writeln!(
        out,
        "| leaders | events | timed from event | seconds | events/s | vs 1 leader | marginals answers during the stream |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|---:|")?;
    let base = streams.first().map(Stream::events_per_second);
    for s in streams {
        writeln!(
            out,
            "| {} | {} | {} | {:.2} | {:.0} | {:.2}× | {} |",
            s.leaders,
            s.events,
            s.first_seen,
            s.seconds,
            s.events_per_second(),
            base.map_or(1.0, |b| s.events_per_second() / b),
            s.queries
        )?;
    }
    writeln!(
        out,
        "\n### Traffic per leader (the paper's Fig. 7(h))\n\nBytes in: the leader's event batches and the sets handed to it; bytes out: the sets it handed to peers (Zenoh framing not counted).\n"
    )?;
    writeln!(
        out,
        "| leaders | leader | items applied | bytes in | bytes out | sets sent | transfers out | bytes out per 1000 events |"
    )?;
    writeln!(out, "|---:|---|---:|---:|---:|---:|---:|---:|")?;
    for s in streams {
        for l in &s.stats {
            writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {} | {:.0} |",
                s.leaders,
                l.leader,
                l.items,
                l.bytes_received,
                l.bytes_sent,
                l.sets_sent,
                l.transfers_sent,
                1000.0 * l.bytes_sent as f64 / s.events as f64
            )?;
        }
    }
    writeln!(out)?;
    Ok(())
}
