//! Who is on which track, computed only when a user asks — the lazy part of
//! Shin et al., *Lazy Inference on Object Identities in Wireless Sensor
//! Networks* (IPSN 2005), Sections 3–4, across processes: leaders keep the
//! rows of the information matrix of their tracks and never normalize; the
//! coordinator collects the rows at a consistent cut, puts the matrix back
//! together and turns it into marginals by the method the query names
//! (`?marginals=auto|exact|metropolis|sinkhorn|bethe`; exact by default up
//! to [`EXACT_BY_DEFAULT`] tracks, `auto` beyond: every independent block
//! of mixed tracks exactly when small, half-Bethe when larger, sampled
//! when larger still — `idmesh_identity::marginals`), then the
//! most likely one-to-one assignment under them (block by block).

use crate::driver::gather::{collect, At, Collected, GatherError, Memory, Share};
use crate::driver::CoordinatorConfig;
use idmesh_identity::factored::assemble;
use idmesh_identity::marginals::DEFAULT_SAMPLES;
use idmesh_identity::{InformationOptions, InformationRows, MarginalMethod};
use idmesh_placement::{from_wire_tree, identity_options};
use idmesh_protocol::wire::identity::MAX_GROUP;
use idmesh_protocol::wire::query::{IdentityAnswer, SamplingReport};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use zenoh::Session;

/// The most tracks for which a query that names no method gets exact
/// marginals (the permanent of an N × N matrix: 2^16 Gray-code steps of
/// N² each, milliseconds; at 22 it is seconds).
pub const EXACT_BY_DEFAULT: usize = 16;

/// The `marginals` an answer of the factored identity belief names: its
/// marginals are the belief's own, exact per group.
pub const FACTORED: &str = "factored-identity";

/// How a query wants its marginals computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Exact up to [`EXACT_BY_DEFAULT`] tracks, `auto` beyond.
    BySize,
    Named(MarginalMethod),
}

impl Method {
    /// `marginals=<name>` (and `samples=`, `seed=` for metropolis) from a
    /// query's parameters.
    pub fn from_parameters(
        marginals: Option<&str>,
        samples: Option<&str>,
        seed: Option<&str>,
    ) -> Result<Method, String> {
        let Some(name) = marginals else {
            return Ok(Method::BySize);
        };
        let samples = match samples {
            None => DEFAULT_SAMPLES,
            Some(s) => s
                .parse()
                .ok()
                .filter(|&s: &usize| s > 0)
                .ok_or_else(|| format!("samples={s}: expected a positive count"))?,
        };
        let seed = match seed {
            None => 0,
            Some(s) => s
                .parse()
                .map_err(|_| format!("seed={s}: expected an unsigned integer"))?,
        };
        MarginalMethod::named(name, samples, seed)
            .map(Method::Named)
            .ok_or_else(|| {
                format!("marginals={name}: expected auto, exact, metropolis, sinkhorn or bethe")
            })
    }

    fn for_tracks(self, n: usize) -> Result<MarginalMethod, GatherError> {
        match self {
            Method::BySize if n <= EXACT_BY_DEFAULT => Ok(MarginalMethod::Exact),
            // Exact on each small block of mixed tracks, half-Bethe or
            // Metropolis on large ones: answers at any size
            // (idmesh_identity::marginals).
            Method::BySize => Ok(MarginalMethod::Auto),
            // Exact takes any n whose blocks are small enough; the engine
            // names the block that is not.
            Method::Named(method) => Ok(method),
        }
    }
}

/// The identity marginals of every track at a consistent cut.
pub async fn identity(
    session: &Session,
    config: &CoordinatorConfig,
    memory: &Memory,
    at: At,
    method: Method,
) -> Result<IdentityAnswer, GatherError> {
    let collected = collect(
        session,
        &config.keys,
        config.timeout,
        memory,
        None,
        at,
        Share::Rows,
    )
    .await?;
    if !collected.cut.identities {
        return Err(GatherError::Failed(
            "the stream carries no identities (its trace header has no `identities`)".into(),
        ));
    }
    let n = collected.cut.tracks as usize;
    // Leaders that hold the factored identity belief answer with trees.
    let trees = collected.parts.iter().any(|p| !p.trees.is_empty());
    if let (Method::Named(named), true) = (method, trees) {
        return Err(GatherError::Failed(format!(
            "marginals={}: a method of the information matrix, and this stream's leaders hold \
             the factored identity belief, whose marginals are its own (ask without marginals=)",
            named.name()
        )));
    }
    let method = method.for_tracks(n)?;
    // Ryser's sum for twenty tracks is a second of arithmetic: keep it off
    // the threads that move messages. A computation past its deadline is
    // stopped (its asker has long given up) instead of holding a thread.
    let stop = Arc::new(AtomicBool::new(false));
    let stopped = stop.clone();
    let task = tokio::task::spawn_blocking(move || match trees {
        true => factored_marginals(&collected),
        false => marginals(collected, method, &stopped),
    });
    let deadline = config.marginals_timeout;
    match tokio::time::timeout(deadline, task).await {
        Ok(done) => {
            done.map_err(|e| GatherError::Failed(format!("the marginals task failed: {e}")))?
        }
        Err(_) => {
            stop.store(true, Ordering::Relaxed);
            Err(GatherError::Failed(format!(
                "{} marginals over {n} tracks did not finish within {deadline:?} (marginals_timeout_ms) and were stopped: ask for a cheaper method (auto, sinkhorn) or fewer samples",
                method.name()
            )))
        }
    }
}

/// The marginals from the trees collected at one cut: the factored
/// identity belief put back together (`IdentityShare`'s `assemble`), its
/// marginals and the most likely assignment under them, as `idmesh
/// replay` computes them.
fn factored_marginals(collected: &Collected) -> Result<IdentityAnswer, GatherError> {
    let n = collected.cut.tracks as usize;
    let failed = |e: idmesh_belief::BeliefError| GatherError::Failed(e.to_string());
    let trees = collected
        .trees()
        .into_iter()
        .map(|t| from_wire_tree(t.clone()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(failed)?;
    // The cap matters only to events to come: the largest one reads any
    // tree the leaders hold.
    let belief = assemble(n, identity_options(MAX_GROUP), trees).map_err(failed)?;
    let p_identity = belief.sparse_marginals().map_err(failed)?;
    let predicted_identity = p_identity.most_likely().map_err(failed)?;
    let p_identity = p_identity.into_rows();
    Ok(IdentityAnswer {
        watermark: collected.watermark(),
        tracks: collected.cut.tracks,
        p_identity,
        predicted_identity,
        marginals: FACTORED.to_string(),
        leaders: collected.parts.len() as u32,
        finished: collected.cut.finished,
        sampling: None,
    })
}

/// The marginals from the rows collected at one cut.
fn marginals(
    collected: Collected,
    method: MarginalMethod,
    stop: &AtomicBool,
) -> Result<IdentityAnswer, GatherError> {
    let n = collected.cut.tracks as usize;
    let rows = collected
        .rows()
        .into_iter()
        .map(|r| (r.track, r.ln_likelihoods.clone()));
    let options = InformationOptions {
        marginals: method,
        ..InformationOptions::default()
    };
    let failed = |e: idmesh_belief::BeliefError| GatherError::Failed(e.to_string());
    let matrix = InformationRows::assemble(n, rows, options).map_err(failed)?;
    // Block by block, as `marginals_with` does, keeping what the sampler
    // says of its convergence.
    let blocks = matrix
        .block_marginals_stoppable(&method, stop)
        .map_err(failed)?;
    // The assignment over the rows, as `idmesh replay` solves it.
    let p_identity = blocks.sparse().map_err(failed)?;
    let predicted_identity = p_identity.most_likely().map_err(failed)?;
    let p_identity = p_identity.into_rows();
    let sampling = blocks.sampling.map(|s| SamplingReport {
        blocks: s.blocks as u32,
        half_difference: s.half_difference,
        acceptance: s.acceptance,
    });
    Ok(IdentityAnswer {
        watermark: collected.watermark(),
        tracks: collected.cut.tracks,
        p_identity,
        predicted_identity,
        marginals: method.name().to_string(),
        leaders: collected.parts.len() as u32,
        finished: collected.cut.finished,
        sampling,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_query_names_its_method_or_gets_one_by_size() {
        let by_size = Method::from_parameters(None, None, None).unwrap();
        assert_eq!(by_size.for_tracks(12).unwrap(), MarginalMethod::Exact);
        assert_eq!(by_size.for_tracks(40).unwrap(), MarginalMethod::Auto);
        let sampled = Method::from_parameters(Some("metropolis"), Some("500"), Some("7")).unwrap();
        assert_eq!(
            sampled.for_tracks(40).unwrap(),
            MarginalMethod::Metropolis {
                samples: 500,
                burn_in: 50,
                seed: 7
            }
        );
        // Exact is passed on at any size: the engine answers when every
        // block of mixed tracks is small and names the block when not.
        let exact = Method::from_parameters(Some("exact"), None, None).unwrap();
        assert_eq!(exact.for_tracks(1000).unwrap(), MarginalMethod::Exact);
        assert!(Method::from_parameters(Some("guess"), None, None).is_err());
        assert!(Method::from_parameters(Some("metropolis"), Some("0"), None).is_err());
        assert!(Method::from_parameters(Some("metropolis"), None, Some("-1")).is_err());
    }
}
