//! Events per second through a deployment: the sensor streams as fast as
//! the mesh takes it, and the bench asks the first leader for its counters
//! every few milliseconds. The stream starts after the last look that saw
//! no event (the question was sent before the first event: the clock
//! starts then) and is through once every leader has been told the stream
//! is over and is quiet (applied every item it was sent, waiting for no
//! peer), and then the coordinator's answer covers all of it: what a user
//! would see, leaders' backlog included. If the bench never saw the stream
//! at zero, it counts from the first look that saw it move.
//!
//! Only the first leader is watched until its last batch says the stream
//! is over; then every leader, until all are quiet. Each look costs the
//! leader asked a wake-up, a question and an answer: watching every leader
//! every 10 ms charged L leaders L times the bench's own watching, and the
//! CPU seconds compared across leader counts are the stream's.
//!
//! It watches the leaders' counters rather than the answers so that every
//! run of the same stream does the same work: a factored answer costs each
//! leader in proportion to what changed since the last, so answers asked
//! every few milliseconds cost a slow deployment (asked more often) more
//! than a fast one, and the CPU seconds compared across leader counts
//! would not be those of the same work. Queries are timed on their own
//! ([`super::latency`]).

use super::interval::median_interval;
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
    pub stats: Vec<LeaderStats>,
    /// CPU seconds each process used while the stream was timed.
    pub cpu: Cpu,
}

/// CPU seconds (user + system) used during a stream, by role.
pub struct Cpu {
    pub sensor: f64,
    pub coordinator: f64,
    /// One per leader.
    pub leaders: Vec<f64>,
}

impl Cpu {
    fn leaders_sum(&self) -> f64 {
        self.leaders.iter().sum()
    }

    fn busiest(&self) -> f64 {
        self.leaders
            .iter()
            .copied()
            .fold(self.sensor.max(self.coordinator), f64::max)
    }
}

/// Of several streams through the same deployment, the one whose
/// leaders' CPU sum is the median (the lower of the middle two).
pub fn median_by_cpu(streams: Vec<Stream>) -> Option<Stream> {
    lower_median(streams, |s| s.cpu.leaders_sum())
}

/// The value whose `key` is the median of all (the lower of the middle
/// two), None of none.
pub(super) fn lower_median<T>(mut values: Vec<T>, key: impl Fn(&T) -> f64) -> Option<T> {
    values.sort_by(|a, b| key(a).total_cmp(&key(b)));
    let middle = values.len().checked_sub(1)? / 2;
    Some(values.swap_remove(middle))
}

impl Stream {
    pub fn events_per_second(&self) -> f64 {
        (self.events - self.first_seen) as f64 / self.seconds
    }
}

pub async fn measure(deployment: &Deployment) -> Result<Stream> {
    let started = Instant::now();
    let mut first: Option<(Instant, u64)> = None;
    let mut last_zero: Option<Instant> = None;
    // The processes' CPU times when the clock starts (read with the last
    // look at zero, or with the first one that moved).
    let mut cpu_at_start = None;
    let watched = deployment
        .topology
        .leader
        .first()
        .map(|l| l.name.clone())
        .ok_or_else(|| anyhow::anyhow!("a deployment without leaders"))?;
    loop {
        let asked = Instant::now();
        let looked = match leader_stats(deployment, &watched).await {
            Ok(looked) => looked,
            Err(e) if first.is_some() => {
                bail!("{watched}'s counters could not be read during the stream: {e}")
            }
            Err(e) if started.elapsed() > START_PATIENCE => {
                bail!("{watched} did not answer within {START_PATIENCE:?}: {e}")
            }
            Err(_) => {
                tokio::time::sleep(POLL).await;
                continue;
            }
        };
        let events = looked.stream_events;
        if events == 0 {
            last_zero = Some(asked);
            cpu_at_start = Some(deployment.cpu_times());
        } else if first.is_none() {
            first = Some(match last_zero {
                Some(zero) => (zero, 0),
                None => {
                    cpu_at_start = Some(deployment.cpu_times());
                    (asked, events)
                }
            });
        }
        if looked.stream_finished {
            break;
        }
        tokio::time::sleep(POLL).await;
    }
    loop {
        let looked = stats(deployment).await.map_err(|e| {
            anyhow::anyhow!("the leaders' counters could not be read during the stream: {e}")
        })?;
        if looked.len() == deployment.leaders && looked.iter().all(|l| l.stream_finished && l.quiet)
        {
            break;
        }
        tokio::time::sleep(POLL).await;
    }
    // The answer that covers the whole stream ends the clock.
    let answer = loop {
        let body = ask(
            &deployment.session,
            &deployment.keys().query_marginals(),
            ASK_TIMEOUT,
        )
        .await?;
        let answer: MarginalsAnswer = serde_json::from_slice(&body)?;
        if answer.finished {
            break answer;
        }
        tokio::time::sleep(POLL).await;
    };
    let events: u64 = answer.watermark.values().sum();
    let (since, first_seen) = first.filter(|(_, seen)| *seen < events).ok_or_else(|| {
        anyhow::anyhow!("the stream was over before the bench could time it: make it longer")
    })?;
    let seconds = since.elapsed().as_secs_f64();
    let used = deployment.cpu_times()?.since(
        &cpu_at_start.ok_or_else(|| anyhow::anyhow!("no CPU reading at the stream's start"))??,
    );
    let topology = &deployment.topology;
    let of = |name: &str| used.get(name).copied().unwrap_or(0.0);
    let cpu = Cpu {
        sensor: of(&topology.sensor().name),
        coordinator: of(&topology.coordinator.name),
        leaders: topology.leader.iter().map(|l| of(&l.name)).collect(),
    };
    Ok(Stream {
        leaders: deployment.leaders,
        events,
        first_seen,
        seconds,
        stats: stats(deployment).await?,
        cpu,
    })
}

/// Waits until the coordinator answers with the stream moving.
pub async fn first_moving_answer(deployment: &Deployment) -> Result<()> {
    watch(deployment, |_, answer| {
        (answer.watermark.values().sum::<u64>() > 0).then_some(())
    })
    .await
}

/// Asks for the marginals every few milliseconds until `seen` (given when
/// each question was sent and its answer) returns something. Until the first
/// answer, errors are the deployment starting up and are borne for a while;
/// after it, an error ends the watch.
async fn watch<T>(
    deployment: &Deployment,
    mut seen: impl FnMut(Instant, &MarginalsAnswer) -> Option<T>,
) -> Result<T> {
    let key = deployment.keys().query_marginals();
    let started = Instant::now();
    let mut answered = false;
    loop {
        let asked = Instant::now();
        match ask(&deployment.session, &key, ASK_TIMEOUT).await {
            Ok(body) => {
                answered = true;
                let answer: MarginalsAnswer = serde_json::from_slice(&body)?;
                if let Some(done) = seen(asked, &answer) {
                    return Ok(done);
                }
            }
            Err(e) if answered => bail!("marginals query failed during the stream: {e}"),
            Err(e) if started.elapsed() > START_PATIENCE => {
                bail!("the deployment did not answer within {START_PATIENCE:?}: {e}")
            }
            Err(_) => {}
        }
        tokio::time::sleep(POLL).await;
    }
}

/// One leader's counters, asked of the leader itself.
async fn leader_stats(deployment: &Deployment, leader: &str) -> Result<LeaderStats> {
    let body = ask(
        &deployment.session,
        &deployment.keys().leader_stats(leader),
        ASK_TIMEOUT,
    )
    .await?;
    Ok(serde_json::from_slice(&body)?)
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

pub fn report(streams: &[Stream], paired: &[PairedCpu], out: &mut String) -> Result<()> {
    writeln!(out, "### Throughput\n")?;
    writeln!(
        out,
        "| leaders | events | timed from event | seconds | events/s | vs 1 leader |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|")?;
    let base = streams.first().map(Stream::events_per_second);
    for s in streams {
        writeln!(
            out,
            "| {} | {} | {} | {:.2} | {:.0} | {:.2}× |",
            s.leaders,
            s.events,
            s.first_seen,
            s.seconds,
            s.events_per_second(),
            base.map_or(1.0, |b| s.events_per_second() / b),
        )?;
    }
    writeln!(
        out,
        "\n### Traffic per leader (the paper's Fig. 7(h))\n\nBytes in: the leader's event batches and the sets handed to it; bytes out: the sets it handed to peers (Zenoh framing not counted). Batches: the messages of the event stream it took in. Follows and unfollows: the requests that grew and shrank the tracks the sensor sends it; tracks followed: how many at the end.\n"
    )?;
    writeln!(
        out,
        "| leaders | leader | items applied | batches | bytes in | bytes out | sets sent | transfers out | bytes out per 1000 events | follows | unfollows | tracks followed |"
    )?;
    writeln!(
        out,
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )?;
    for s in streams {
        for l in &s.stats {
            writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {:.0} | {} | {} | {} |",
                s.leaders,
                l.leader,
                l.items,
                l.batches,
                l.bytes_received,
                l.bytes_sent,
                l.sets_sent,
                l.transfers_sent,
                1000.0 * l.bytes_sent as f64 / s.events as f64,
                l.follows,
                l.unfollows,
                l.tracks_followed
            )?;
        }
    }
    writeln!(
        out,
        "\n### CPU seconds while the stream was timed (user + system, each process, from /proc)\n\nAll processes share this machine's cores, so the wall clock above cannot show scale-out; these can. *Hosts bound*: the events/s a deployment with a host per process would reach if the busiest process were the limit (timed events ÷ its CPU seconds).\n"
    )?;
    writeln!(
        out,
        "| leaders | sensor | coordinator | leaders, sum | busiest leader | leaders' sum vs 1 leader | hosts bound, events/s |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|---:|")?;
    let one = streams.first().map(|s| s.cpu.leaders_sum());
    for s in streams {
        let sum = s.cpu.leaders_sum();
        let busiest = s.cpu.leaders.iter().copied().fold(0.0, f64::max);
        writeln!(
            out,
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2}× | {:.0} |",
            s.leaders,
            s.cpu.sensor,
            s.cpu.coordinator,
            sum,
            busiest,
            one.map_or(1.0, |o| sum / o),
            (s.events - s.first_seen) as f64 / s.cpu.busiest()
        )?;
    }
    writeln!(out)?;
    goals(streams, paired, out)
}

/// One leader count's CPU against one leader's, round by round: each
/// round streams every leader count back to back, so a ratio within a
/// round is taken at one speed of this machine, whose speed drifts by a
/// fifth over minutes; the medians of the rounds' sums, taken apart, can
/// come from rounds far apart.
pub struct PairedCpu {
    pub leaders: usize,
    /// The leaders' CPU sum ÷ the same round's one leader's, by round.
    pub rounds: Vec<f64>,
}

impl PairedCpu {
    /// The median of the rounds' ratios (the lower of the middle two).
    pub fn median(&self) -> Option<f64> {
        lower_median(self.rounds.clone(), |&r| r)
    }

    /// The interval that holds the ratio's median with 95% confidence
    /// ([`median_interval`]); None under six rounds.
    pub fn interval(&self) -> Option<(f64, f64, f64)> {
        median_interval(&self.rounds)
    }
}

/// For every leader count past one, its rounds' CPU ratios against the
/// one-leader streams of the same rounds. `runs`: by leader count, each
/// by round (a count without a one-leader run pairs with nothing).
pub fn paired_cpu(runs: &[Vec<Stream>]) -> Vec<PairedCpu> {
    let Some(one) = runs
        .iter()
        .find(|r| r.first().is_some_and(|s| s.leaders == 1))
    else {
        return Vec::new();
    };
    runs.iter()
        .filter_map(|r| {
            let leaders = r.first()?.leaders;
            (leaders > 1).then(|| PairedCpu {
                leaders,
                rounds: r
                    .iter()
                    .zip(one)
                    .map(|(s, o)| s.cpu.leaders_sum() / o.cpu.leaders_sum())
                    .collect(),
            })
        })
        .collect()
}

/// The scale-out goals, read off a run: at every leader count
/// past one, the busiest leader's items against an even share of what one
/// leader applies alone, and the leaders' CPU sum against one leader's.
pub struct ScaleOut {
    pub leaders: usize,
    /// Busiest leader's items ÷ (one leader's items / L).
    pub items: f64,
    /// Leaders' CPU sum ÷ one leader's.
    pub cpu: f64,
}

/// The goals' bound on both ratios.
const SCALE_OUT_GOAL: f64 = 1.5;

/// The ratios of every stream with more than one leader, against the run's
/// one-leader stream (None without one).
pub fn scale_out(streams: &[Stream]) -> Option<Vec<ScaleOut>> {
    let one = streams.iter().find(|s| s.leaders == 1)?;
    let one_items = one.stats.iter().map(|l| l.items).sum::<u64>() as f64;
    let one_cpu = one.cpu.leaders_sum();
    Some(
        streams
            .iter()
            .filter(|s| s.leaders > 1)
            .map(|s| {
                let busiest = s.stats.iter().map(|l| l.items).max().unwrap_or(0) as f64;
                ScaleOut {
                    leaders: s.leaders,
                    items: busiest / (one_items / s.leaders as f64),
                    cpu: s.cpu.leaders_sum() / one_cpu,
                }
            })
            .collect(),
    )
}

fn goals(streams: &[Stream], paired: &[PairedCpu], out: &mut String) -> Result<()> {
    let Some(rows) = scale_out(streams) else {
        return Ok(());
    };
    if rows.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "### Scale-out goals

The busiest leader's items against an even share of what one leader applies alone (its items ÷ L), and the leaders' CPU sum against one leader's (the rows above); the goal is at most {SCALE_OUT_GOAL}× for both. The last column takes the CPU ratio within each round, against the same round's one leader, and gives their median, the interval that holds the median with 95% confidence whatever the rounds' spread (from six rounds on: order statistics), and every round's ratio.
"
    )?;
    writeln!(
        out,
        "| leaders | busiest leader's items ÷ even share | leaders' CPU ÷ one leader's | the same, round by round |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|")?;
    let mark = |x: f64| {
        if x <= SCALE_OUT_GOAL {
            "met"
        } else {
            "not met"
        }
    };
    for r in rows {
        let rounds = paired.iter().find(|p| p.leaders == r.leaders);
        let by_round = match rounds.and_then(|p| Some((p.median()?, p))) {
            Some((median, p)) => format!(
                "{median:.2}× ({}; {}{})",
                mark(median),
                match p.interval() {
                    Some((low, high, sure)) => format!(
                        "{:.0}% interval {low:.2}–{high:.2}× over {} rounds; ",
                        sure * 100.0,
                        p.rounds.len()
                    ),
                    None => String::new(),
                },
                p.rounds
                    .iter()
                    .map(|x| format!("{x:.2}×"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            None => "—".to_string(),
        };
        writeln!(
            out,
            "| {} | {:.2}× ({}) | {:.2}× ({}) | {by_round} |",
            r.leaders,
            r.items,
            mark(r.items),
            r.cpu,
            mark(r.cpu)
        )?;
    }
    writeln!(out)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stream(items: &[u64], cpu: &[f64]) -> Stream {
        Stream {
            leaders: items.len(),
            events: 1000,
            first_seen: 0,
            seconds: 1.0,
            stats: items
                .iter()
                .map(|&items| LeaderStats {
                    items,
                    ..LeaderStats::default()
                })
                .collect(),
            cpu: Cpu {
                sensor: 0.0,
                coordinator: 0.0,
                leaders: cpu.to_vec(),
            },
        }
    }

    #[test]
    fn the_median_stream_is_the_middle_one_by_the_leaders_cpu() {
        let runs = vec![
            stream(&[10], &[0.9]),
            stream(&[20], &[0.5]),
            stream(&[30], &[0.7]),
            stream(&[40], &[0.6]),
        ];
        let median = median_by_cpu(runs).expect("four runs");
        assert_eq!(median.stats[0].items, 40, "0.6 is the lower middle");
        let one = median_by_cpu(vec![stream(&[7], &[0.3])]).unwrap();
        assert_eq!(one.stats[0].items, 7);
        assert!(median_by_cpu(Vec::new()).is_none());
    }

    #[test]
    fn the_goals_compare_the_busiest_leader_and_the_cpu_sum_with_one_leader() {
        let runs = [
            stream(&[1000], &[0.5]),
            stream(&[300, 700], &[0.5, 0.5]),
            stream(&[250, 250, 250, 400], &[0.1, 0.1, 0.2, 0.3]),
        ];
        let rows = scale_out(&runs).expect("a one-leader run");
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].leaders, 2);
        assert!((rows[0].items - 1.4).abs() < 1e-12, "700 ÷ (1000 / 2)");
        assert!((rows[0].cpu - 2.0).abs() < 1e-12);
        assert!((rows[1].items - 1.6).abs() < 1e-12, "400 ÷ (1000 / 4)");
        assert!((rows[1].cpu - 1.4).abs() < 1e-12);
        assert!(scale_out(&runs[1..]).is_none(), "nothing to compare with");
    }

    /// The goals section of a run's rounds, each leader count's row from
    /// its median stream.
    fn goals_of(runs: Vec<Vec<Stream>>, paired: &[PairedCpu]) -> String {
        let mut report = String::new();
        let streams: Vec<Stream> = runs.into_iter().filter_map(median_by_cpu).collect();
        goals(&streams, paired, &mut report).unwrap();
        report
    }

    /// Round by round, each ratio is against the same round's one leader:
    /// a slow round (every stream 1.5× the CPU) reads as fast ones do.
    #[test]
    fn cpu_ratios_pair_each_round_with_its_own_one_leader() {
        let runs = vec![
            vec![
                stream(&[9], &[0.5]),
                stream(&[9], &[0.75]),
                stream(&[9], &[0.4]),
            ],
            vec![
                stream(&[5, 5], &[0.35, 0.35]),
                stream(&[5, 5], &[0.5, 0.55]),
                stream(&[5, 5], &[0.3, 0.3]),
            ],
        ];
        let paired = paired_cpu(&runs);
        assert_eq!(paired.len(), 1);
        assert_eq!(paired[0].leaders, 2);
        let expected = [1.4, 1.4, 1.5];
        for (got, want) in paired[0].rounds.iter().zip(expected) {
            assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        }
        let median = paired[0].median().expect("three rounds");
        assert!((median - 1.4).abs() < 1e-12, "{median}");
        assert!(paired_cpu(&runs[1..]).is_empty(), "no one-leader run");
        let report = goals_of(runs, &paired);
        assert!(
            report.contains("1.40× (met; 1.40×, 1.40×, 1.50×)"),
            "{report}"
        );
    }

    /// From six rounds on, the median comes with the interval that holds
    /// it with 95% confidence: here every round but the extremes.
    #[test]
    fn enough_rounds_give_the_median_its_interval() {
        let ones = [0.5; 9];
        let fours = [0.8, 0.6, 0.7, 0.75, 0.65, 1.0, 0.72, 0.68, 0.55];
        let runs = vec![
            ones.iter().map(|&c| stream(&[9], &[c])).collect::<Vec<_>>(),
            fours
                .iter()
                .map(|&c| stream(&[3, 2, 2, 2], &[c / 4.0; 4]))
                .collect(),
        ];
        let paired = paired_cpu(&runs);
        let (low, high, sure) = paired[0].interval().expect("nine rounds");
        assert!(
            (low - 1.2).abs() < 1e-9 && (high - 1.6).abs() < 1e-9,
            "{low} {high}"
        );
        assert!(sure > 0.95);
        let report = goals_of(runs, &paired);
        assert!(
            report.contains("1.40× (met; 96% interval 1.20–1.60× over 9 rounds; 1.60×, 1.20×"),
            "{report}"
        );
    }
}
