//! Who is on which track, computed only when a user asks — the lazy part of
//! Shin et al., *Lazy Inference on Object Identities in Wireless Sensor
//! Networks* (IPSN 2005), Sections 3–4, across processes: leaders keep the
//! rows of the information matrix of their tracks and never normalize; the
//! coordinator collects the rows at a consistent cut, puts the matrix back
//! together and turns it into marginals by the method the query names
//! ([`Method`]), then the most likely one-to-one assignment under them
//! (block by block). Leaders that hold the factored identity belief send
//! their trees instead, put back together as `idmesh replay` does.

use super::gather::{collect, At, Collected, GatherError, Memory, Share};
use super::CoordinatorConfig;
use crate::identity::{Method, FACTORED};
use idmesh_identity::factored::assemble;
use idmesh_identity::{InformationOptions, InformationRows, MarginalMethod};
use idmesh_placement::{from_wire_tree, identity_options};
use idmesh_protocol::wire::identity::MAX_GROUP;
use idmesh_protocol::wire::query::{IdentityAnswer, SamplingReport};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use zenoh::Session;

/// The identity marginals of every track at a consistent cut.
pub(crate) async fn identity(
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
