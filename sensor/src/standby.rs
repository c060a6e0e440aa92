//! The sensor's standby, and the sensor's side of it: the I/O around the
//! pure replication machine (`crate::machine::replication`).
//!
//! On the sensor: a [`Replicator`] sends every group of records the
//! sensor appends to its journal to one of its standbys (a get on
//! `P/sensor/<name>/replicate/<standby>`) and waits for its answer before
//! what depends on them leaves, while that standby's liveliness token is
//! present. Which standby, among several, is the pure machine
//! `crate::machine::standbys`'s choice: the first present, kept while it
//! stays; when it goes, with voters, the role moves to a new epoch before
//! the next is chosen and sent the whole journal, compacted. With none
//! present the sensor goes on alone.
//!
//! On a standby's process (its own host, its own disk): [`stand_by`]
//! keeps the copy, `<state_dir>/<sensor>.standby.journal` (a sensor
//! journal like the sensor's own, under another name so that processes
//! sharing a disk never collide), and watches the sensor's token. Once it
//! has been gone for the takeover time, and the topology has voters, it
//! claims the sensor role through them naming the epoch it fences off
//! (`idmesh-claims`); won, it hands its copy back as the sensor's journal,
//! and the process serves as the sensor from it ([`crate::run`]).
//!
//! The lease ([`keep_lease`]): a holder of the sensor role that cannot
//! read the map from a leading voter for the lease time, or reads that
//! the role is another's, stops serving, so that a cut-off former sensor
//! never acts beside its successor.

use crate::journal::{self, Journal, JournalError, Record};
use crate::lease::LeaseClock;
use crate::machine::replication::{Apply, Copy, Presence, Replication, Step};
use crate::machine::standbys::{Change, Standbys};
use crate::machine::Gateway;
use idmesh_claims::{verdict, Claimed, Claims, Verdict};
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::sensor_to_standby::{Position, Replicate, Replicated};
use idmesh_protocol::wire::{decode, encode, VERSION};
use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::Subscriber;
use zenoh::query::Query;
use zenoh::sample::{Sample, SampleKind};
use zenoh::Session;

/// The role a sensor's standby declares its liveliness token under
/// (`P/alive/sensor-standby/<name>`).
pub const STANDBY_ROLE: &str = "sensor-standby";

/// How long the sensor waits for its standby's answer before it sends
/// the same records again (the token still present).
const ANSWER_PATIENCE: Duration = Duration::from_secs(1);

/// How often the standby looks whether the takeover is due, and a holder
/// reads the map to keep its lease.
const LOOK_EVERY: Duration = Duration::from_millis(250);

/// How long a sensor waits before it claims its role again when no
/// voter decided.
const HELD_WAIT: Duration = Duration::from_secs(2);

/// How long one claim may wait for the voters' decision.
const CLAIM_PATIENCE: Duration = Duration::from_secs(5);

#[derive(Debug, thiserror::Error)]
pub enum StandbyError {
    #[error("zenoh: {what}: {message}")]
    Mesh { what: &'static str, message: String },
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// Records the standby did not acknowledge, and the voters did not
    /// move the role here to a new epoch since the standby went.
    #[error(
        "sensor {role}: its standby is gone and the voters did not move the role here to a new \
         epoch: what the standby does not hold is not released"
    )]
    Unconfirmed { role: String },
    #[error("sensor {role}: the voters give it to {holder} at epoch {epoch}, not to {me}")]
    Held {
        role: String,
        me: String,
        holder: String,
        epoch: u64,
    },
}

fn mesh(what: &'static str) -> impl FnOnce(zenoh::Error) -> StandbyError {
    move |e| StandbyError::Mesh {
        what,
        message: e.to_string(),
    }
}

/// Where a standby keeps, under `dir`, its copy of `sensor`'s journal.
pub fn standby_path(dir: &Path, sensor: &str) -> PathBuf {
    dir.join(format!("{sensor}.standby.journal"))
}

type Tokens = Subscriber<FifoChannelHandler<Sample>>;

/// The sensor's side: its standbys' tokens watched, its records sent to
/// the one chosen.
pub(crate) struct Replicator {
    session: Session,
    keys: Keys,
    choice: Standbys,
    machine: Replication,
    tokens: Tokens,
    /// With voters: the role's lease ([`crate::lease`]).
    lease: Option<LeaseClock>,
    /// When the standby replicated to was last seen gone (or the start):
    /// records it did not acknowledge leave only under an advance of the
    /// role asked since.
    gone_since: Instant,
}

impl Replicator {
    /// Replicates sensor `sensor`'s journal to one of the processes
    /// `standbys` (in order of preference); with voters, under the role's
    /// `lease`.
    pub(crate) async fn start(
        session: &Session,
        keys: &Keys,
        sensor: &str,
        standbys: &[String],
        lease: Option<LeaseClock>,
    ) -> Result<Self, StandbyError> {
        let tokens = session
            .liveliness()
            .declare_subscriber(keys.alive_role(STANDBY_ROLE))
            .history(true)
            .await
            .map_err(mesh("watch the standbys' tokens"))?;
        // Drawn at start: positions of an earlier run of this sensor mean
        // nothing to this one.
        let incarnation = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        let mut machine = Replication::new(sensor, incarnation);
        machine.at_epoch(lease.as_ref().map_or(0, LeaseClock::epoch));
        let mut replicator = Replicator {
            session: session.clone(),
            keys: keys.clone(),
            choice: Standbys::new(standbys.to_vec(), lease.is_some()),
            machine,
            tokens,
            lease,
            gone_since: Instant::now(),
        };
        replicator.drain();
        Ok(replicator)
    }

    /// The standby the journal is replicated to now, if one is up (the
    /// replication is told every change of the choice: [`Self::apply`]).
    pub(crate) fn current(&self) -> Option<&str> {
        self.choice.current()
    }

    /// The next change of a standby's token.
    pub(crate) async fn changed(&self) -> Option<Sample> {
        self.tokens.recv_async().await.ok()
    }

    /// A change of a standby's token: whether the journal is to be sent
    /// at once, not at the next append (a standby was chosen, or one is
    /// there to be chosen once the role has moved on).
    pub(crate) fn token(&mut self, sample: &Sample) -> bool {
        let present = sample.kind() == SampleKind::Put;
        let name = Keys::chunk(sample.key_expr().as_str(), 0).unwrap_or_default();
        let mut chosen = false;
        for change in self.choice.token(name, present) {
            chosen |= self.apply(change);
        }
        chosen || self.choice.waiting()
    }

    /// A change of the standby replicated to, told to the replication:
    /// whether one was chosen.
    fn apply(&mut self, change: Change) -> bool {
        match change {
            Change::Gone(standby) => {
                if self.machine.standby(false) == Some(Presence::Gone) {
                    self.gone_since = Instant::now();
                    tracing::warn!(%standby,
                        "the sensor's standby is gone: the sensor goes on without it until another is chosen");
                }
                false
            }
            Change::Chosen(standby) => {
                if self.machine.standby(true) == Some(Presence::Back) {
                    tracing::info!(%standby, "the sensor replicates to this standby: sending it the journal");
                }
                true
            }
        }
    }

    /// Every token change that has come.
    fn drain(&mut self) {
        while let Ok(Some(sample)) = self.tokens.try_recv() {
            self.token(&sample);
        }
    }

    /// Records `appended` to the journal (and fsynced; `compacted`: the
    /// journal was compacted right after): returns once the standby holds
    /// them, or once it is gone — with voters, once the role is also moved
    /// to an epoch past the standby's copy since it went (that epoch: what
    /// leaves the sensor from then on carries it), and an error if the hold
    /// is lost instead (then nothing that depends on them may leave).
    pub(crate) async fn replicate(
        &mut self,
        appended: &[Record],
        compacted: bool,
        gateway: &Gateway<Query>,
    ) -> Result<Option<u64>, StandbyError> {
        self.drain();
        if compacted {
            self.machine.compacted();
        }
        let started = Instant::now();
        let mut step = self
            .machine
            .appended(appended.iter().map(journal::encode).collect());
        let mut moved = None;
        loop {
            self.send(step, gateway).await;
            // Gone, the standby may have gone because the voters gave it
            // the role, or only be cut off from here while its copy could
            // still win it: the records it did not acknowledge leave only
            // once the voters have moved the role here to an epoch past its
            // copy's (an advance asked since it went, which also says the
            // role is held here); and only then is another standby chosen.
            // Without voters none can take the role over.
            let (true, Some(lease)) = (self.choice.fence_due(), &self.lease) else {
                break;
            };
            let Some(epoch) = lease.advanced_since(self.gone_since).await else {
                return Err(StandbyError::Unconfirmed {
                    role: self.machine.sensor().to_string(),
                });
            };
            self.machine.at_epoch(epoch);
            moved = Some(epoch);
            let Some(change) = self.choice.fenced() else {
                break;
            };
            // The standby chosen takes the whole journal, in sync at the
            // new epoch, before anything leaves.
            self.apply(change);
            step = self.machine.appended(Vec::new());
        }
        let waited = started.elapsed();
        if waited > ANSWER_PATIENCE {
            tracing::info!(standby = ?self.choice.current(), seconds = waited.as_secs_f64(),
                present = self.machine.present(), "a slow replication to the standby");
        }
        Ok(moved)
    }

    /// Drives the replication from `step` until what was appended may
    /// leave: the standby holds it, or none is replicated to.
    async fn send(&mut self, mut step: Step, gateway: &Gateway<Query>) {
        loop {
            let message = match step {
                Step::Release => return,
                Step::Send(message) => message,
                Step::NeedWhole => match gateway.compacted() {
                    Ok(records) => self
                        .machine
                        .whole(records.iter().map(journal::encode).collect()),
                    Err(e) => {
                        // Tried again at the next append.
                        tracing::error!(error = %e, "could not snapshot the sensor's state for its standby");
                        return;
                    }
                },
            };
            let answer = self.ask(&message).await;
            self.drain();
            step = self.machine.answered(answer);
        }
    }

    /// Sends `message` and waits for the answer: the copy's position
    /// (`Some(None)`: none of this run), `None` if none came in time.
    async fn ask(&self, message: &Replicate) -> Option<Option<Position>> {
        let standby = self.choice.current()?;
        let replies = self
            .session
            .get(self.keys.sensor_replicate(self.machine.sensor(), standby))
            .payload(encode(message))
            .timeout(ANSWER_PATIENCE)
            .await
            .ok()?;
        while let Ok(reply) = replies.recv_async().await {
            let Ok(sample) = reply.result() else { continue };
            match decode::<Replicated>(&sample.payload().to_bytes()) {
                Ok(answer) if answer.standby == standby => return Some(answer.position),
                Ok(answer) => {
                    tracing::warn!(from = %answer.standby, "a replication answer from a process that is not the standby")
                }
                Err(e) => tracing::warn!(error = %e, "a replication answer that does not read"),
            }
        }
        None
    }
}

/// The standby process's settings.
#[derive(Debug, Clone)]
pub struct StandbyConfig {
    /// This process.
    pub name: String,
    /// The sensor it stands by for.
    pub sensor: String,
    pub keys: Keys,
    /// Its copy of the sensor's journal ([`standby_path`]).
    pub journal: PathBuf,
    /// How long the sensor's token must be gone before the takeover.
    pub takeover_after: Duration,
    /// With voters, the lease; None: no voters, and no takeover (the
    /// copy is kept all the same).
    pub lease: Option<Duration>,
    /// `journal` is this process's own journal, left by its earlier
    /// holding of the role (a former sensor standing by for the process
    /// that took its role over): emptied before it stands by. Past where
    /// the role left it, it holds records its successor never had, so the
    /// role must never be taken over from it; the holder sends its whole
    /// journal in its place.
    pub earlier_holding: bool,
}

/// How standing by ended.
pub enum Standing {
    /// Shut down while standing by.
    Shutdown,
    /// The voters gave this process the sensor role at `epoch`: it serves
    /// as the sensor from its copy (`journal`, holding `records`), and
    /// keeps the lease with `claims`.
    TookOver(Box<TookOver>),
}

/// The sensor role won: its epoch, the copy opened as the sensor's
/// journal with the records it holds, and the voters' client that keeps
/// the lease.
pub struct TookOver {
    pub epoch: u64,
    pub journal: Journal,
    pub records: Vec<Record>,
    pub claims: Claims,
}

/// Keeps the copy of the sensor's journal and watches the sensor, until
/// `shutdown` or until this process has won the sensor role.
pub async fn stand_by(
    session: &Session,
    config: &StandbyConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<Standing, StandbyError> {
    let keys = &config.keys;
    let (mut journal, mut copy, kept) = open_copy(config)?;
    let queries = session
        .declare_queryable(keys.sensor_replicate(&config.sensor, &config.name))
        .await
        .map_err(mesh("declare the replication queryable"))?;
    let sensor = session
        .liveliness()
        .declare_subscriber(keys.alive("sensor", &config.sensor))
        .history(true)
        .await
        .map_err(mesh("watch the sensor's token"))?;
    let token = session
        .liveliness()
        .declare_token(keys.alive(STANDBY_ROLE, &config.name))
        .await
        .map_err(mesh("declare the liveliness token"))?;
    let mut claims = config
        .lease
        .map(|lease| Claims::new(session.clone(), keys.clone(), &config.name, lease));
    // A copy kept from before counts the sensor gone from now; with none,
    // the sensor has not been up yet and nothing is to be taken over.
    let mut gone_since = kept.then(Instant::now);
    let mut told_why = false;
    let mut look = tokio::time::interval(LOOK_EVERY);
    tokio::pin!(shutdown);
    tracing::info!(sensor = %config.sensor, copy = %config.journal.display(), "standing by for the sensor");
    loop {
        tokio::select! {
            _ = &mut shutdown => return Ok(Standing::Shutdown),
            query = queries.recv_async() => {
                let Ok(query) = query else { return Ok(Standing::Shutdown) };
                keep(&query, config, &mut copy, &mut journal).await?;
            }
            sample = sensor.recv_async() => {
                let Ok(sample) = sample else { continue };
                gone_since = match sample.kind() {
                    SampleKind::Put => None,
                    SampleKind::Delete => {
                        tracing::warn!(sensor = %config.sensor, "the sensor's token is gone");
                        Some(Instant::now())
                    }
                };
            }
            _ = look.tick() => {
                let due = gone_since.is_some_and(|at| at.elapsed() >= config.takeover_after);
                // A copy that holds nothing of the sensor's: the sensor went
                // on alone while this process was away, and what it sent
                // then is nowhere here.
                if due && !kept && copy.position.is_none() {
                    if !told_why {
                        tracing::warn!(sensor = %config.sensor,
                            "the sensor is gone, but this standby holds nothing of its journal: not taking it over");
                        told_why = true;
                    }
                    continue;
                }
                let (true, Some(voters)) = (due, claims.as_mut()) else { continue };
                let Some(in_sync) = copy.epoch else {
                    if !told_why {
                        tracing::warn!(sensor = %config.sensor, copy = %epoch_path(&config.journal).display(),
                            "the sensor is gone, but this standby's copy does not say at which epoch it was in sync: not taking it over");
                        told_why = true;
                    }
                    continue;
                };
                match take_over(voters, &config.sensor, in_sync).await {
                    Some(epoch) => {
                        drop((queries, sensor, token, journal));
                        serving_from(&config.journal, epoch)?;
                        let (journal, records) = Journal::open(&config.journal, &config.name)?;
                        let Some(claims) = claims.take() else {
                            return Ok(Standing::Shutdown);
                        };
                        return Ok(Standing::TookOver(Box::new(TookOver { epoch, journal, records, claims })));
                    }
                    // Another holds it: it came back, or another process
                    // won. Looked at again after another takeover time.
                    None => gone_since = gone_since.map(|_| Instant::now()),
                }
            }
        }
    }
}

/// Claims `role` naming `in_sync`, the epoch at which the copy holds
/// every record the sensor sent: the epoch won, or None. It loses once
/// the sensor has moved its role on (it went on without this copy), or
/// another process holds it.
async fn take_over(claims: &mut Claims, role: &str, in_sync: u64) -> Option<u64> {
    tracing::warn!(sensor = %role, fencing = in_sync, "the sensor has been gone for the takeover time: claiming its role");
    match claims.claim(role, Some(in_sync), CLAIM_PATIENCE).await {
        Claimed::Won(epoch) => {
            tracing::warn!(sensor = %role, epoch, "the voters gave this process the sensor role: taking over from the copy");
            Some(epoch)
        }
        Claimed::Lost { holder, epoch } if epoch > in_sync => {
            tracing::warn!(sensor = %role, %holder, epoch, in_sync,
                "the sensor role moved past the epoch this copy is in sync at (the sensor went on without it, or another took over): standing by");
            None
        }
        Claimed::Lost { holder, epoch } => {
            tracing::info!(sensor = %role, %holder, epoch, "the sensor role is held: standing by");
            None
        }
        Claimed::Undecided => None,
    }
}

/// Where the epoch of the sensor journal at `journal` is kept: the newest
/// epoch at which it held every record the role released (a copy's, in
/// sync; a holder's own, held). A takeover from the journal names it.
pub fn epoch_path(journal: &Path) -> PathBuf {
    let mut path = journal.as_os_str().to_owned();
    path.push(".epoch");
    PathBuf::from(path)
}

/// What an epoch file's header says it holds: the epoch of a copy of the
/// holder's journal ([`keep`]) …
const COPY_EPOCH: &str = "sensor-copy";
/// … or the epoch at which this process held the role itself
/// ([`serving_from`]).
const HELD_EPOCH: &str = "sensor-held";

/// Whose a journal is, by its epoch file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kept {
    /// A copy of the holder's, in sync at this epoch.
    Copy(u64),
    /// This process's own, written holding the role at this epoch.
    Held(u64),
}

fn read_kept(journal: &Path) -> Result<Option<Kept>, StandbyError> {
    let path = epoch_path(journal);
    let read = |kind| idmesh_journal::read_number(&path, kind);
    let kept = match read(COPY_EPOCH) {
        Err(idmesh_journal::Error::WrongKind { .. }) => read(HELD_EPOCH).map(|e| e.map(Kept::Held)),
        copy => copy.map(|e| e.map(Kept::Copy)),
    };
    Ok(kept.map_err(JournalError::from)?)
}

/// Opens the standby's copy: its journal, where it is (the epoch it holds
/// every record of, from its epoch file), and whether it holds records
/// kept from before.
///
/// A journal of this process's own earlier holding, standing by for the
/// process that took the role over from it, is emptied first: past where
/// the role left it, it holds records the holder never had. One that is
/// a copy of the holder's (it stood by already, and restarted) is kept.
fn open_copy(config: &StandbyConfig) -> Result<(Journal, Copy, bool), StandbyError> {
    let (mut journal, records) = Journal::open(&config.journal, &config.name)?;
    let kept = read_kept(&config.journal)?;
    let epoch = match (config.earlier_holding, kept) {
        (true, Some(Kept::Copy(epoch))) => {
            if !records.is_empty() {
                tracing::warn!(sensor = %config.sensor, journal = %config.journal.display(), epoch,
                    "this process's journal of the sensor role is its copy of the holder's: kept, standing by for the holder");
            }
            Some(epoch)
        }
        (true, _) => {
            if !records.is_empty() {
                journal.replace_encoded(&[])?;
                tracing::warn!(sensor = %config.sensor, journal = %config.journal.display(),
                    "this process's journal of the sensor role is of an earlier holding: emptied, standing by for the holder");
            }
            idmesh_journal::remove_file(&epoch_path(&config.journal))
                .map_err(JournalError::from)?;
            return Ok((journal, Copy::default(), false));
        }
        // A dedicated standby's: its copy, or the journal of its own
        // holding (it held the role, and restarted): a claim naming that
        // epoch gives the role back while it is still its own.
        (false, Some(Kept::Copy(epoch) | Kept::Held(epoch))) => Some(epoch),
        (false, None) => None,
    };
    let copy = Copy {
        position: None,
        epoch,
    };
    Ok((journal, copy, !records.is_empty()))
}

/// This process serves the sensor role at `epoch` from the journal at
/// `journal` (its own, or a copy it took the role over from): noted in the
/// epoch file, whole, before it serves ([`open_copy`] reads it).
pub fn serving_from(journal: &Path, epoch: u64) -> Result<(), StandbyError> {
    idmesh_journal::write_number(&epoch_path(journal), HELD_EPOCH, epoch)
        .map_err(JournalError::from)?;
    Ok(())
}

/// A replication request: its records on the copy's disk, then the
/// copy's position as the answer.
async fn keep(
    query: &Query,
    config: &StandbyConfig,
    copy: &mut Copy,
    journal: &mut Journal,
) -> Result<(), StandbyError> {
    let bytes = query
        .payload()
        .map(|p| p.to_bytes().into_owned())
        .unwrap_or_default();
    let message = match decode::<Replicate>(&bytes) {
        Ok(m) if m.sensor == config.sensor => m,
        Ok(m) => {
            return refuse(
                query,
                format!("records of {}, not {}", m.sensor, config.sensor),
            )
            .await
        }
        Err(e) => return refuse(query, e.to_string()).await,
    };
    // Records that do not read are not kept: the copy must restore.
    if let Some(e) = message
        .records
        .iter()
        .find_map(|r| journal::decode_record(r).err())
    {
        return refuse(query, format!("a record that does not decode: {e}")).await;
    }
    let in_sync = copy.epoch;
    match copy.take(&message) {
        Apply::Replace(records) => journal.replace_encoded(records)?,
        Apply::Append(records) => journal.append_encoded(records)?,
        Apply::Nothing => {}
    }
    // On disk before the answer: a takeover after a restart names it.
    if let Some(epoch) = copy.epoch.filter(|_| copy.epoch != in_sync) {
        idmesh_journal::write_number(&epoch_path(&config.journal), COPY_EPOCH, epoch)
            .map_err(JournalError::from)?;
    }
    let answer = Replicated {
        version: VERSION,
        standby: config.name.clone(),
        position: copy.position,
    };
    if let Err(e) = query.reply(query.key_expr().clone(), encode(&answer)).await {
        tracing::debug!(error = %e, "a replication answer was not sent");
    }
    Ok(())
}

async fn refuse(query: &Query, reason: String) -> Result<(), StandbyError> {
    tracing::warn!(%reason, "a replication request refused");
    let _ = query.reply_err(reason).await;
    Ok(())
}

/// Who serves a sensor role, as its own process found when it started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Owned {
    /// This process, at this epoch.
    Here(u64),
    /// Another process (its standby took it over, said at warn level):
    /// this one stands by for it ([`stand_by`] with
    /// [`StandbyConfig::earlier_holding`]).
    Elsewhere,
}

/// With voters, before a sensor serves its own role: claims it (a
/// sensor coming back to a role it holds keeps its epoch). A role the
/// voters give to another is not fenced off: this process's journal
/// stopped where the role left it. Asks again while no voter decides.
pub async fn claim_own(claims: &mut Claims, role: &str, me: &str) -> Owned {
    loop {
        match claims.claim(role, None, CLAIM_PATIENCE).await {
            Claimed::Won(epoch) => return Owned::Here(epoch),
            Claimed::Lost { holder, epoch } => {
                let held = StandbyError::Held {
                    role: role.to_string(),
                    me: me.to_string(),
                    holder,
                    epoch,
                };
                tracing::warn!(sensor = %role, "{held}: standing by for it");
                return Owned::Elsewhere;
            }
            Claimed::Undecided => {
                tracing::warn!(sensor = %role, "no leading voter answered the sensor's claim: asking again");
                tokio::time::sleep(HELD_WAIT).await;
            }
        }
    }
}

/// Returns once this process (`me`) may no longer serve `role` (held at
/// the epoch on `clock`): the map gives the role to another, or no voter
/// has led for the lease. The holder then stops serving, and the loss is
/// noted on `clock`; an advance the replication asks for
/// ([`LeaseClock::advanced_since`]) is made here, through the voters, and
/// noted there too.
pub async fn keep_lease(mut claims: Claims, role: String, me: String, clock: LeaseClock) {
    let since = Instant::now();
    // When the last advance was asked: one the voters made after its
    // proposer stopped waiting shows as the role here past the epoch.
    let mut proposed: Option<Instant> = None;
    loop {
        tokio::time::sleep(LOOK_EVERY).await;
        if let Some(map) = claims.read().await {
            if let (Some(asked), Some(entry)) = (proposed, map.get(&role)) {
                if entry.holder.as_deref() == Some(me.as_str()) && entry.epoch > clock.epoch() {
                    clock.advanced(asked, entry.epoch);
                }
            }
            match verdict(map, &role, &me, clock.epoch()) {
                Verdict::Holds => {}
                Verdict::Superseded { holder, epoch: now } => {
                    tracing::warn!(sensor = %role, ?holder, epoch = now, "the voters gave the sensor role to another: stopping");
                    clock.lose();
                    return;
                }
            }
        }
        if clock.advance_due() {
            let asked = Instant::now();
            proposed = Some(asked);
            let from = clock.epoch();
            match claims.advance(&role, from, CLAIM_PATIENCE).await {
                Claimed::Won(epoch) => {
                    tracing::warn!(sensor = %role, from, epoch,
                        "the sensor goes on without its standby: its role moved to a new epoch, which the standby's copy cannot take over");
                    clock.advanced(asked, epoch);
                }
                Claimed::Lost { holder, epoch } => {
                    tracing::warn!(sensor = %role, %holder, epoch, "the voters gave the sensor role to another: stopping");
                    clock.lose();
                    return;
                }
                // Asked again at the next look, while the lease holds.
                Claimed::Undecided => {}
            }
        }
        if claims.lapsed(since) {
            tracing::warn!(sensor = %role, lease = ?claims.lease,
                "no leading voter for the lease: stopping the sensor role");
            clock.lose();
            return;
        }
    }
}
