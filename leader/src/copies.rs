//! Standby copies asked of the other processes at an adoption.
//!
//! A role's standby is the process that would adopt it, and it changes
//! with the processes that are up: a process that has just started (on an
//! empty disk, or with an old copy) becomes the heir of a role before the
//! role's first snapshot reached it, while the process that was the
//! standby until then keeps a newer copy — and the sensor and the peers
//! have forgotten what lies before that copy's mark (the mark a role
//! publishes waits for its standby's copy, and never steps back). Lost
//! in that window, the role adopted from what the heir holds could not be
//! rebuilt. So an adopter asks every live process for the copy it keeps
//! of the role (`P/leader/<role>/copy/<process>`), and keeps the newest
//! one if it is newer than its own, before it decides and adopts; a
//! journal of the role in its own state directory (a shared disk) is
//! newer than any copy, and then nothing is asked.

use crate::host::HostConfig;
use crate::standby::{self, behind, standby_path};
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_leader::StandbyCopy;
use idmesh_protocol::wire::leader_to_sensor::Durable;
use idmesh_protocol::wire::{decode, encode, VERSION};
use std::time::Duration;
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::{Query, Queryable};
use zenoh::Session;

/// How long an adopter waits for the other processes' copies.
const ASK_PATIENCE: Duration = Duration::from_secs(1);

/// The queryable on which this process answers for the copies it keeps.
pub(crate) type Asked = Queryable<FifoChannelHandler<Query>>;

/// Answers, for every role, with the copy this process keeps of it.
pub(crate) async fn declare(session: &Session, config: &HostConfig) -> zenoh::Result<Asked> {
    session
        .declare_queryable(config.keys.leader_copy("*", &config.name))
        .await
}

/// Answers `query` (`P/leader/<role>/copy/*`) with the copy of the role
/// this process keeps, if it keeps one.
pub(crate) async fn answer(config: &HostConfig, query: &Query) {
    let Some(dir) = &config.state_dir else {
        return;
    };
    let Some(role) = Keys::chunk(query.key_expr().as_str(), 2) else {
        return;
    };
    if !config.leaders.iter().any(|l| l == role) {
        return;
    }
    let (mark, state) = match standby::read(&standby_path(dir, role)) {
        Ok(Some(copy)) => copy,
        Ok(None) => return,
        Err(e) => {
            tracing::warn!(process = %config.name, role, error = %e,
                "a standby copy asked for by an adopter cannot be read");
            return;
        }
    };
    let copy = StandbyCopy {
        version: VERSION,
        role: role.to_string(),
        to: config.name.clone(),
        mark,
        state,
    };
    let key = config.keys.leader_copy(role, &config.name);
    if let Err(e) = query.reply(key, encode(&copy)).await {
        tracing::debug!(process = %config.name, role, error = %e, "a standby copy was not sent");
    }
}

/// Before adopting `role`: asks every live process for the copy it keeps
/// and keeps the newest here if it is newer than this process's own. A
/// journal of the role the adoption would start from wins over any copy
/// (with voters, `last`: one written in the holding the map names last).
pub(crate) async fn take_newest(
    session: &Session,
    config: &HostConfig,
    role: &str,
    last: Option<u64>,
) {
    let Some(dir) = &config.state_dir else {
        return;
    };
    // This process's own state of the role: a journal wins over any copy;
    // with voters the standby copy's mark comes from the same read.
    let own = match last {
        Some(last) => match standby::adoption_source(dir, role, last) {
            Ok(standby::Source::Journal) => return,
            Ok(standby::Source::StandbyCopy(mark)) => Some(mark),
            // None kept, or a damaged one: any other is better.
            Ok(standby::Source::Nothing) | Err(_) => None,
        },
        None if standby::journal_kept(dir, role) => return,
        None => match standby::read(&standby_path(dir, role)) {
            Ok(copy) => copy.map(|(mark, _)| mark),
            Err(_) => None,
        },
    };
    let Ok(replies) = session
        .get(config.keys.every_leader_copy(role))
        .timeout(ASK_PATIENCE)
        .await
    else {
        return;
    };
    let mut copies = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        let Ok(sample) = reply.result() else {
            continue;
        };
        match decode::<StandbyCopy>(&sample.payload().to_bytes()) {
            Ok(copy) if copy.role == role && copy.to != config.name => copies.push(copy),
            Ok(_) => {}
            Err(e) => tracing::warn!(process = %config.name, role, error = %e,
                "a standby copy from another process refused"),
        }
    }
    let Some(copy) = newest(copies, own.as_ref()) else {
        return;
    };
    match standby::keep(dir, &copy, &config.name) {
        Ok(_) => tracing::warn!(process = %config.name, role, from = %copy.to,
            batch = copy.mark.batch, position = copy.mark.position,
            "took a newer standby copy of the role from another process"),
        Err(e) => tracing::warn!(process = %config.name, role, error = %e,
            "a newer standby copy from another process could not be kept"),
    }
}

/// Of `copies`, the one with the newest mark, if `own` (this process's
/// copy's mark) is behind it or there is none.
fn newest(copies: Vec<StandbyCopy>, own: Option<&Durable>) -> Option<StandbyCopy> {
    let newest = copies
        .into_iter()
        .max_by_key(|c| (c.mark.batch, c.mark.position))?;
    own.is_none_or(|own| behind(own, &newest.mark))
        .then_some(newest)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn copy(from: &str, batch: u64, position: u64) -> StandbyCopy {
        StandbyCopy {
            version: VERSION,
            role: "l1".into(),
            to: from.into(),
            mark: mark(batch, position),
            state: Vec::new(),
        }
    }

    fn mark(batch: u64, position: u64) -> Durable {
        Durable {
            version: VERSION,
            epoch: 0,
            leader: "l1".into(),
            batch,
            position,
        }
    }

    /// The newest of the others' copies is kept, and only if this
    /// process's own is behind it.
    #[test]
    fn the_newest_copy_is_taken_only_over_an_older_one() {
        let others = || vec![copy("l0", 3, 40), copy("l3", 5, 61), copy("l2", 4, 50)];
        let to = |c: Option<StandbyCopy>| c.map(|c| c.to);
        assert_eq!(to(newest(others(), None)), Some("l3".into()), "none here");
        assert_eq!(to(newest(others(), Some(&mark(2, 30)))), Some("l3".into()));
        assert_eq!(to(newest(others(), Some(&mark(5, 61)))), None, "the same");
        assert_eq!(to(newest(others(), Some(&mark(6, 70)))), None, "newer here");
        assert_eq!(to(newest(Vec::new(), None)), None, "nobody keeps one");
    }
}
