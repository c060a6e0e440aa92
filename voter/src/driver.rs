//! The voter's I/O driver: a thin loop around `idmesh_consensus::Voter`.
//! It ticks the machine at a fixed period, steps it with the raft messages
//! and proposals that come over Zenoh, writes what each step asks to
//! persist to the voter's log (fsynced), and only then sends the step's
//! messages. A log that cannot be written stops the voter (its supervisor
//! starts it again from the log): a voter that went on without its log
//! could vote twice in a term.

use idmesh_consensus::{
    Command, ConsensusError, DurableError, DurableLog, Envelope, Outcome, Voter, VoterConfig,
};
use idmesh_protocol::wire::keys::Keys;
use std::future::Future;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::mpsc;
use zenoh::Session;

/// One voter process.
#[derive(Debug, Clone)]
pub struct VoterProcess {
    /// Its place in the group (id, every voter's id, election timing).
    pub voter: VoterConfig,
    pub keys: Keys,
    /// Its log file.
    pub log: PathBuf,
    /// One tick of the machine's clock: elections take
    /// `election_ticks` of them, heartbeats `heartbeat_ticks`.
    pub tick: Duration,
}

#[derive(Debug, thiserror::Error)]
pub enum VoterError {
    #[error("voter log: {0}")]
    Log(#[from] DurableError),
    #[error("voter: {0}")]
    Consensus(#[from] ConsensusError),
    #[error("zenoh: {0}")]
    Zenoh(zenoh::Error),
    #[error("a command that does not encode: {0}")]
    Encode(#[from] postcard::Error),
}

/// What came for the voter.
enum Incoming {
    Raft(Vec<u8>),
    Propose(Vec<u8>),
}

/// Messages waiting for the loop; past this a burst is dropped, which
/// Raft takes as lost messages.
const QUEUE: usize = 4096;

/// Proposes `command` to the voters of `keys`' deployment: any voter takes
/// it, and raft forwards it to the leader. Decided when the map shows it
/// (`query/roles`); lost if the leader changes first, so a claimant reads
/// the map back and proposes again.
pub async fn propose(session: &Session, keys: &Keys, command: &Command) -> Result<(), VoterError> {
    let bytes = postcard::to_allocvec(command)?;
    session
        .put(keys.raft_propose(), bytes)
        .await
        .map_err(VoterError::Zenoh)
}

/// Runs the voter until `shutdown`.
pub async fn run(
    session: Session,
    config: VoterProcess,
    shutdown: impl Future<Output = ()>,
) -> Result<(), VoterError> {
    let id = config.voter.id;
    let (mut log, storage) = DurableLog::open(&config.log, &config.voter.voters)?;
    let mut voter = Voter::new(&config.voter, storage)?;
    let (tx, mut rx) = mpsc::channel::<Incoming>(QUEUE);
    let raft_tx = tx.clone();
    let _raft = session
        .declare_subscriber(config.keys.raft(id))
        .callback(move |sample| {
            let _ = raft_tx.try_send(Incoming::Raft(sample.payload().to_bytes().to_vec()));
        })
        .await
        .map_err(VoterError::Zenoh)?;
    let _proposals = session
        .declare_subscriber(config.keys.raft_propose())
        .callback(move |sample| {
            let _ = tx.try_send(Incoming::Propose(sample.payload().to_bytes().to_vec()));
        })
        .await
        .map_err(VoterError::Zenoh)?;
    let answer = Arc::new(Mutex::new(voter.roles_answer()));
    let shown = answer.clone();
    let roles_key = config.keys.query_roles();
    let reply_key = roles_key.clone();
    let _roles = session
        .declare_queryable(&roles_key)
        .callback(move |query| {
            use zenoh::Wait;
            let body = match shown.lock() {
                Ok(answer) => serde_json::to_vec(&*answer).unwrap_or_default(),
                Err(_) => return,
            };
            if let Err(e) = query.reply(&reply_key, body).wait() {
                tracing::debug!(error = %e, "could not answer a roles query");
            }
        })
        .await
        .map_err(VoterError::Zenoh)?;
    tracing::info!(voter = id, voters = ?config.voter.voters, "voter started");
    let mut ticker = tokio::time::interval(config.tick);
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => voter.tick(),
            Some(incoming) = rx.recv() => take(&mut voter, incoming),
        }
        let ready = voter.ready();
        log.write(&ready.persist)?;
        for envelope in ready.send {
            let bytes = envelope.encode()?;
            if let Err(e) = session.put(config.keys.raft(envelope.to), bytes).await {
                // A lost message: raft sends again.
                tracing::debug!(to = envelope.to, error = %e, "a raft message was not sent");
            }
        }
        for outcome in voter.take_outcomes() {
            match outcome {
                Outcome::Changed { role, holding } => tracing::info!(
                    voter = id,
                    %role,
                    holder = ?holding.holder,
                    epoch = holding.epoch,
                    "role changed hands"
                ),
                Outcome::Unchanged { role, why } => {
                    tracing::debug!(voter = id, %role, why, "claim decided: unchanged")
                }
            }
        }
        if let Ok(mut shown) = answer.lock() {
            *shown = voter.roles_answer();
        }
    }
    Ok(())
}

/// Steps the machine with what came; what does not decode or is refused
/// is logged and passed over (raft treats it as lost).
fn take(voter: &mut Voter, incoming: Incoming) {
    match incoming {
        Incoming::Raft(bytes) => match Envelope::decode(&bytes) {
            Ok(envelope) if envelope.to == voter.id() => {
                if let Err(e) = voter.step(envelope.message) {
                    tracing::debug!(from = envelope.from, error = %e, "a raft message was refused");
                }
            }
            Ok(envelope) => {
                tracing::warn!(to = envelope.to, "a raft message for another voter")
            }
            Err(e) => tracing::warn!(error = %e, "a raft message that does not decode"),
        },
        // Every voter hears a proposal; the leader alone takes it (one
        // entry, not one per voter). With no leader it is lost, and the
        // claimant, reading the map back, proposes again.
        Incoming::Propose(_) if !voter.is_leader() => {}
        Incoming::Propose(bytes) => match postcard::from_bytes::<Command>(&bytes) {
            Ok(command) => {
                if let Err(e) = voter.propose(&command) {
                    tracing::debug!(error = %e, "a proposal was not taken");
                }
            }
            Err(e) => tracing::warn!(error = %e, "a proposal that does not decode"),
        },
    }
}
