//! `idmesh query marginals|track T|identity [T]|positions|stats`: a Zenoh client of
//! the user API.
//! Human-readable by default, `--json` prints the reply as it came.
//! `--ca`, `--cert`, `--key` reach a secured deployment over mutual TLS.

use super::mesh::{self, MeshOptions};
use super::security::Tls;
use anyhow::{anyhow, bail, Result};
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::query::{
    IdentityAnswer, IdentityTrackAnswer, MarginalsAnswer, PositionsAnswer, QueryError,
    SamplingReport, StatsAnswer, TrackAnswer, Watermark,
};
use std::io::Write;
use std::time::{Duration, Instant};

#[derive(Debug, Clone)]
pub struct QueryOptions {
    pub what: Question,
    pub connect: String,
    pub prefix: String,
    pub json: bool,
    pub timeout: Duration,
    /// Ask this many times (for watching a stream), `interval` apart.
    pub repeat: u32,
    pub interval: Duration,
    /// Ask instead, all at once, for the answers right after these event
    /// counts (`?events=N`), printed in this order.
    pub at_events: Vec<u64>,
    /// How identity marginals are computed (`?marginals=`); None = the
    /// coordinator's choice.
    pub marginals: Option<String>,
    /// Metropolis's counted steps per block (`?samples=`).
    pub samples: Option<u64>,
    /// A secured deployment: the CA and this client's certificate (its
    /// common name listed in the topology's `[security] clients`).
    pub tls: Option<Tls>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Question {
    Marginals,
    Track(u32),
    /// Every track's identities, or one track's.
    Identity(Option<u32>),
    /// Where every track was last seen, and its leader.
    Positions,
    Stats,
    /// Who holds each role, as every voter's committed log has it.
    Roles,
}

pub fn run(options: &QueryOptions) -> Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let session = connect(options).await?;
        let keys = Keys::new(options.prefix.clone());
        let key = match options.what {
            Question::Marginals => keys.query_marginals(),
            Question::Track(t) => keys.query_track(t),
            Question::Identity(None) => keys.query_identity(),
            Question::Identity(Some(t)) => keys.query_identity_track(t),
            Question::Positions => keys.query_positions(),
            Question::Stats => keys.query_stats(),
            Question::Roles => {
                let result = roles(&session, &keys, options.timeout).await;
                let _ = session.close().await;
                return result;
            }
        };
        let parameters: Vec<String> = options
            .marginals
            .iter()
            .map(|m| format!("marginals={m}"))
            .chain(options.samples.map(|s| format!("samples={s}")))
            .collect();
        if !options.at_events.is_empty() {
            return at_events(&session, &key, &parameters, options).await;
        }
        let key = selector(&key, &parameters);
        let mut failures = 0;
        for i in 0..options.repeat.max(1) {
            if i > 0 {
                tokio::time::sleep(options.interval).await;
            }
            let started = Instant::now();
            match ask(&session, &key, options.timeout).await {
                Ok(body) => print(options, &body, started.elapsed())?,
                Err(e) => {
                    failures += 1;
                    eprintln!("{key}: {e}");
                }
            }
        }
        let _ = session.close().await;
        if failures > 0 {
            bail!("{failures} of {} queries failed", options.repeat.max(1));
        }
        Ok(())
    })
}

/// Every voter's answer on `query/roles`, one JSON line each, by voter id
/// (each voter answers from its own log: a voter cut off may lag).
async fn roles(session: &zenoh::Session, keys: &Keys, timeout: Duration) -> Result<()> {
    let replies = session
        .get(keys.query_roles())
        .target(zenoh::query::QueryTarget::All)
        .consolidation(zenoh::query::ConsolidationMode::None)
        .timeout(timeout)
        .await
        .map_err(|e| anyhow!("{e}"))?;
    let mut answers: Vec<idmesh_voter::RolesAnswer> = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            answers.push(serde_json::from_slice(&sample.payload().to_bytes())?);
        }
    }
    if answers.is_empty() {
        bail!("no voter answered within {timeout:?}: does the topology name [[voter]]s?");
    }
    answers.sort_by_key(|a| a.voter);
    for answer in answers {
        println!("{}", serde_json::to_string(&answer)?);
    }
    Ok(())
}

/// A client session to the coordinator at `--connect`. Zenoh's own error
/// (a source location inside the zenoh crate) goes to the debug log; the
/// user is told what is most likely wrong.
async fn connect(options: &QueryOptions) -> Result<zenoh::Session> {
    mesh::open(&MeshOptions {
        client: true,
        listen: vec![],
        connect: mesh::endpoint_list(&options.connect),
        tls: options.tls.clone(),
        ..MeshOptions::default()
    })
    .await
    .map_err(|error| {
        if error.downcast_ref::<mesh::NoSession>().is_none() {
            return error;
        }
        tracing::debug!(%error, "zenoh could not connect");
        anyhow!(
            "no deployment answers at {}: is `idmesh demo` or `idmesh up` running, and is \
             that the coordinator's endpoint (`--connect`)?",
            options.connect
        )
    })
}

/// `key?a;b;…`, or the key alone.
fn selector(key: &str, parameters: &[String]) -> String {
    if parameters.is_empty() {
        key.to_string()
    } else {
        format!("{key}?{}", parameters.join(";"))
    }
}

/// Every `--at-events` point asked at once; the answers in point order.
async fn at_events(
    session: &zenoh::Session,
    key: &str,
    parameters: &[String],
    options: &QueryOptions,
) -> Result<()> {
    let asked: Vec<_> = options
        .at_events
        .iter()
        .map(|n| {
            let mut at = parameters.to_vec();
            at.push(format!("events={n}"));
            let (session, selector) = (session.clone(), selector(key, &at));
            let timeout = options.timeout;
            tokio::spawn(async move {
                let started = Instant::now();
                let answer = ask(&session, &selector, timeout).await;
                (selector, answer, started.elapsed())
            })
        })
        .collect();
    let mut failures = 0;
    for handle in asked {
        let (selector, answer, took) = handle.await?;
        match answer {
            Ok(body) => print(options, &body, took)?,
            Err(e) => {
                failures += 1;
                eprintln!("{selector}: {e}");
            }
        }
    }
    let _ = session.clone().close().await;
    if failures > 0 {
        bail!(
            "{failures} of {} points were not answered",
            options.at_events.len()
        );
    }
    Ok(())
}

/// One get; the reply body, or the error reply's message. Express: the
/// reply takes the question's QoS, and an express reply is not held back
/// for a Zenoh batch to fill.
pub async fn ask(session: &zenoh::Session, key: &str, timeout: Duration) -> Result<Vec<u8>> {
    let replies = session
        .get(key)
        .express(true)
        .timeout(timeout)
        .await
        .map_err(|e| anyhow!("{e}"))?;
    let reply = tokio::time::timeout(timeout + Duration::from_secs(1), replies.recv_async())
        .await
        .map_err(|_| anyhow!("no reply within {timeout:?}"))?
        .map_err(|_| anyhow!("no reply: is the coordinator up and listening there?"))?;
    match reply.result() {
        Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
        Err(e) => {
            let body = e.payload().to_bytes();
            let message = serde_json::from_slice::<QueryError>(&body)
                .map(|q| q.error)
                .unwrap_or_else(|_| String::from_utf8_lossy(&body).into_owned());
            bail!("{message}")
        }
    }
}

/// What a user reads of a Metropolis answer's convergence.
fn sampling_line(s: &SamplingReport) -> String {
    let verdict = if s.half_difference <= 0.01 {
        "mixed"
    } else {
        "not mixed: ask with more samples (?marginals=metropolis;samples=…)"
    };
    format!(
        "  sampled {} block(s) by Metropolis: halves differ by up to {:.3}, {:.0} % of proposals accepted ({verdict})",
        s.blocks,
        s.half_difference,
        s.acceptance * 100.0
    )
}

fn print(options: &QueryOptions, body: &[u8], took: Duration) -> Result<()> {
    let mut out = std::io::stdout().lock();
    if options.json {
        out.write_all(body)?;
        writeln!(out)?;
        return Ok(());
    }
    match options.what {
        Question::Marginals => {
            let a: MarginalsAnswer = serde_json::from_slice(body)?;
            writeln!(
                out,
                "{} ({}) · {} leaders · {} sets · {:.1} ms",
                events(&a.watermark),
                if a.finished {
                    "stream over"
                } else {
                    "streaming"
                },
                a.leaders,
                a.coefficients,
                took.as_secs_f64() * 1e3
            )?;
            writeln!(out, "predicted red: {:?}", a.predicted_red)?;
            for (t, p) in a.p_red.iter().enumerate() {
                writeln!(out, "  track {t:>4}  P(red) = {p:.4}")?;
            }
        }
        Question::Track(_) => {
            let a: TrackAnswer = serde_json::from_slice(body)?;
            writeln!(out, "track {}: P(red) = {:.4}", a.track, a.p_red)?;
        }
        Question::Identity(None) => {
            let a: IdentityAnswer = serde_json::from_slice(body)?;
            writeln!(
                out,
                "{} · {} leaders · {} marginals · {:.1} ms",
                events(&a.watermark),
                a.leaders,
                a.marginals,
                took.as_secs_f64() * 1e3
            )?;
            if let Some(s) = &a.sampling {
                writeln!(out, "{}", sampling_line(s))?;
            }
            for (t, (row, &i)) in a.p_identity.iter().zip(&a.predicted_identity).enumerate() {
                let p = row.probability(i);
                writeln!(out, "  track {t:>4}  identity {i:>4}  P = {p:.4}")?;
            }
        }
        Question::Identity(Some(_)) => {
            let a: IdentityTrackAnswer = serde_json::from_slice(body)?;
            let i = a.predicted_identity;
            let p = a.p_identity.probability(i);
            writeln!(out, "track {}: identity {i} (P = {p:.4})", a.track)?;
            if let Some(s) = &a.sampling {
                writeln!(out, "{}", sampling_line(s))?;
            }
        }
        Question::Positions => {
            let a: PositionsAnswer = serde_json::from_slice(body)?;
            writeln!(out, "{}", events(&a.watermark))?;
            for (t, (at, &owner)) in a.positions.iter().zip(&a.owners).enumerate() {
                let leader = a
                    .leaders
                    .get(owner as usize)
                    .map_or("?", |l| l.name.as_str());
                match at {
                    Some([x, y]) => writeln!(out, "  track {t:>4}  ({x:.2}, {y:.2})  {leader}")?,
                    None => writeln!(out, "  track {t:>4}  not seen yet  {leader}")?,
                }
            }
        }
        Question::Stats => {
            let a: StatsAnswer = serde_json::from_slice(body)?;
            writeln!(
                out,
                "{:<12} {:>9} {:>9} {:>9} {:>10} {:>10} {:>8} {:>7}",
                "leader", "items", "mixes", "observes", "bytes in", "bytes out", "sets", "follows"
            )?;
            for l in a.leaders {
                writeln!(
                    out,
                    "{:<12} {:>9} {:>9} {:>9} {:>10} {:>10} {:>8} {:>7}",
                    l.leader,
                    l.items,
                    l.mixes,
                    l.observations,
                    l.bytes_received,
                    l.bytes_sent,
                    l.coefficients,
                    l.follows
                )?;
            }
        }
        // Answered apart (`roles`): every voter's, not one.
        Question::Roles => {}
    }
    Ok(())
}

/// "sensor-0: 1200 events, …"
fn events(watermark: &Watermark) -> String {
    let events: Vec<String> = watermark
        .iter()
        .map(|(s, e)| format!("{s}: {e} events"))
        .collect();
    events.join(", ")
}
