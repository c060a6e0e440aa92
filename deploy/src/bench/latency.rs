//! Query latency against the physical floor. Each round asks, one after the
//! other: the coordinator for the marginals; the coordinator's ping (one
//! raw get round trip); and every leader's ping at once (the raw fan-out a
//! marginals query has to make anyway). Interleaving puts the three under
//! the same noise.

use super::Deployment;
use crate::runtime::query::ask;
use anyhow::{bail, Result};
use idmesh_protocol::wire::query::MarginalsAnswer;
use std::fmt::Write as _;
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(10);
const WARM_UP: usize = 50;

pub struct Latencies {
    pub leaders: usize,
    pub marginals: Vec<Duration>,
    pub ping_one: Vec<Duration>,
    pub ping_leaders: Vec<Duration>,
    /// At rest only: every leader's partial sums where it rests, fetched
    /// straight from the leaders (the leaders' share of a query, without
    /// the coordinator).
    pub partials: Vec<Duration>,
}

/// Times `queries` rounds; `streaming` checks that the stream was still
/// running when the last marginals answer came.
pub async fn measure(
    deployment: &Deployment,
    queries: usize,
    streaming: bool,
) -> Result<Latencies> {
    let keys = deployment.keys();
    let marginals_key = keys.query_marginals();
    let coordinator = keys.ping("coordinator", &deployment.topology.coordinator.name);
    let leaders = keys.every_ping("leader");
    let mut l = Latencies {
        leaders: deployment.leaders,
        marginals: Vec::with_capacity(queries),
        ping_one: Vec::with_capacity(queries),
        ping_leaders: Vec::with_capacity(queries),
        partials: Vec::with_capacity(if streaming { 0 } else { queries }),
    };
    let partials_key = format!("{}?quiet", keys.every_leader_partial());
    // The bench's session connects to each process on its own; wait until
    // it reaches them all.
    deployment
        .wait_for(&leaders, deployment.leaders, TIMEOUT)
        .await?;
    let mut finished = false;
    for round in 0..WARM_UP + queries {
        let started = Instant::now();
        let body = ask(&deployment.session, &marginals_key, TIMEOUT).await?;
        let marginals = started.elapsed();
        finished = serde_json::from_slice::<MarginalsAnswer>(&body)?.finished;
        let started = Instant::now();
        deployment.ping(&coordinator, 1).await?;
        let one = started.elapsed();
        let started = Instant::now();
        deployment.ping(&leaders, deployment.leaders).await?;
        let fan_out = started.elapsed();
        let partials = if streaming {
            None
        } else {
            let started = Instant::now();
            deployment.ping(&partials_key, deployment.leaders).await?;
            Some(started.elapsed())
        };
        if round >= WARM_UP {
            l.partials.extend(partials);
            l.marginals.push(marginals);
            l.ping_one.push(one);
            l.ping_leaders.push(fan_out);
        }
    }
    if streaming && finished {
        bail!("the stream ended before the queries did: make it longer or slower");
    }
    Ok(l)
}

pub fn percentile(samples: &[Duration], p: f64) -> Duration {
    let mut sorted = samples.to_vec();
    sorted.sort();
    let rank = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

pub fn report(l: &Latencies, when: &str, out: &mut String) -> Result<()> {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let row = |name: &str, samples: &[Duration], out: &mut String| -> Result<()> {
        let (p50, p99) = (percentile(samples, 0.5), percentile(samples, 0.99));
        writeln!(
            out,
            "| {name} | {:.3} | {:.3} | {:.1}× | {:.1}× | {:.1}× | {:.1}× |",
            ms(p50),
            ms(p99),
            ms(p50) / ms(percentile(&l.ping_one, 0.5)),
            ms(p99) / ms(percentile(&l.ping_one, 0.99)),
            ms(p50) / ms(percentile(&l.ping_leaders, 0.5)),
            ms(p99) / ms(percentile(&l.ping_leaders, 0.99)),
        )?;
        Ok(())
    };
    writeln!(
        out,
        "### Query latency, {} leaders, {when} ({} queries of each kind, interleaved)\n",
        l.leaders,
        l.marginals.len()
    )?;
    writeln!(
        out,
        "| get | p50 ms | p99 ms | p50 / one get | p99 / one get | p50 / fan-out | p99 / fan-out |"
    )?;
    writeln!(out, "|---|---:|---:|---:|---:|---:|---:|")?;
    row("`query/marginals`", &l.marginals, out)?;
    row("raw get, one process", &l.ping_one, out)?;
    row(
        &format!("raw get fanned out to {} leaders", l.leaders),
        &l.ping_leaders,
        out,
    )?;
    if !l.partials.is_empty() {
        row(
            "the leaders' partial sums where they rest, fetched straight",
            &l.partials,
            out,
        )?;
    }
    writeln!(out)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_take_the_sample_at_or_above_the_rank() {
        let samples: Vec<Duration> = (1..=100).rev().map(Duration::from_millis).collect();
        assert_eq!(percentile(&samples, 0.5), Duration::from_millis(50));
        assert_eq!(percentile(&samples, 0.99), Duration::from_millis(99));
        assert_eq!(percentile(&samples[..1], 0.99), Duration::from_millis(100));
    }
}
