//! A leader process: hosts its own leader role and, when another role is
//! gone for good, adopts it.
//!
//! Membership is Zenoh liveliness: every role's actor holds the token
//! `P/alive/leader/<role>` while it runs. A token that disappears and does
//! not come back within [`HostConfig::takeover_after`] means the process
//! died for good; the role passes to the process hosting the next live
//! role in the deployment's list (cyclically), which every process works
//! out the same way from the same tokens. The adopter starts an actor for
//! the role beside its own: it recovers the role's state from its snapshot
//! and journal in the shared state directory, then fetches what those miss
//! from the sensor (batches after the journal's last) and from the peers
//! (transfers since) — the same catch-up a restarted leader does. The
//! role's tracks, sets and rows are thus reassigned to a surviving process
//! without changing the stream's routing: the keys are the role's, not the
//! process's.
//!
//! A token can vanish without its process dying: a partition hides it.
//! So a role is adopted only if its journal's lock is free
//! (`idmesh_ownership`): a process that still runs the role, however
//! cut off, keeps it, and the role stays missing (answers `degraded`,
//! naming it) until the cut heals, instead of running twice.
//!
//! Until the role is adopted nobody answers for it, and the coordinator's
//! answer says which leaders are missing; while the adopted actor catches
//! up it answers with a "degraded: recovering" error. Never numbers without
//! the role's share.
//!
//! Hosts need not share a disk. Each role's standby is the process that
//! would adopt it — the heir as above, counted without the roles its own
//! process hosts, which die with it — and keeps a copy of the role's last
//! snapshot under its own state directory (`crate::standby`; the role's
//! durable mark waits for it, `crate::machine`). A process adopting a
//! role whose journal it does not find installs that copy as the role's
//! snapshot and catches up from there; a journal of the role it does find
//! (a shared disk) is newer, and is used.
//!
//! Roles go home. A process that starts and finds its own role's token
//! held (adopted while it was away, or its old session's token not yet
//! expired) stands by and says so with a token of its own,
//! `P/alive/home/<name>`. The process that adopted the role sees it and
//! hands the role back: it stops the role's actor, which syncs the
//! journal and then drops the role's token. The standby takes its role as
//! soon as that token is gone — with or without takeover — and recovers
//! it from the journal the adopter left in the shared state directory
//! (the state moves; nothing is rebuilt from the stream's start), then
//! fetches what that misses as any restarted leader does. Load is back in
//! balance.

use crate::copies;
use crate::driver::{self, LeaderConfig};
use crate::error::{MeshError, RunError};
use crate::journal::{JournalError, JournalOptions};
use crate::standby::{self, Source};
use idmesh_claims::{self as claims, Claimed, Claims, Verdict};
use idmesh_ownership::OwnershipError;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_leader::{StandbyCopy, StandbyStored};
use idmesh_protocol::wire::leader_to_sensor::Durable;
use idmesh_protocol::wire::{decode, encode};
use std::collections::{BTreeSet, HashMap};
use std::future::Future;
use std::path::PathBuf;
use std::time::{Duration, Instant};
use tokio::sync::watch;
use tokio::task::JoinSet;
use zenoh::sample::SampleKind;
use zenoh::Session;

#[derive(Debug, Clone)]
pub struct HostConfig {
    /// This process (and the role it hosts first).
    pub name: String,
    pub keys: Keys,
    /// Every leader role of the deployment, in the stream's order.
    pub leaders: Vec<String>,
    pub sensor: String,
    pub follow_timeout: Duration,
    /// Where every role keeps its journal; shared by the processes that
    /// may adopt one another's roles. None = no journal, no adoption.
    pub state_dir: Option<PathBuf>,
    pub fsync_every: Duration,
    pub snapshot_every: Option<usize>,
    /// How long a role may be without its token before it is adopted;
    /// None = never (it stays missing until its process returns).
    pub takeover_after: Option<Duration>,
    /// Tests only: every n-th transfer put is lost on purpose.
    pub drop_transfer_every: Option<u64>,
    /// Tests only: every n-th answer pushed at a cut is lost on purpose.
    pub drop_push_every: Option<u64>,
    /// The sensor streams under a window: leaders mark their progress
    /// after every input (else at their sweeps only).
    pub flow_control: bool,
    /// With voters in the topology: roles are claimed through them
    /// ([`idmesh_claims`]), and the roles here stop when no voter has led
    /// for this long. None: no voters; the tokens and, on a shared disk,
    /// the journal's lock decide.
    pub lease: Option<Duration>,
    /// Every role sends its snapshots to a standby on another leader
    /// process's disk (with more than one leader and a state directory).
    /// Off only where the leaders share a disk that survives any host:
    /// the role's own journal is then there for its adopter.
    pub standbys: bool,
}

impl HostConfig {
    /// Whether every role keeps a standby: asked for, more than one leader
    /// process, and a state directory to keep copies in.
    fn standbys(&self) -> bool {
        self.standbys && self.leaders.len() > 1 && self.state_dir.is_some()
    }

    /// The actor settings for `role`, hosted here.
    fn role(
        &self,
        role: &str,
        adopted: bool,
        epoch: u64,
        standby: Option<watch::Receiver<Option<String>>>,
    ) -> LeaderConfig {
        LeaderConfig {
            name: role.to_string(),
            host: self.name.clone(),
            epoch,
            adopted,
            keys: self.keys.clone(),
            sensor: self.sensor.clone(),
            follow_timeout: self.follow_timeout,
            journal: self.state_dir.as_ref().map(|dir| JournalOptions {
                path: journal_path(dir, role),
                fsync_every: self.fsync_every,
            }),
            snapshot_every: self.snapshot_every,
            drop_transfer_every: self.drop_transfer_every,
            drop_push_every: self.drop_push_every,
            flow_control: self.flow_control,
            standby,
        }
    }

    /// Who holds `role`'s journal now, if anyone does (always None
    /// without a state directory: nothing to fence, nothing to adopt).
    fn journal_holder(&self, role: &str) -> Option<String> {
        let dir = self.state_dir.as_ref()?;
        idmesh_ownership::held_by(&journal_path(dir, role))
    }
}

/// Where role `role` keeps its journal under `dir`.
pub(crate) fn journal_path(dir: &std::path::Path, role: &str) -> PathBuf {
    dir.join(format!("{role}.journal"))
}

/// The role that inherits `dead`: the next live one after it in `leaders`,
/// cyclically. Every process computes the same from the same tokens.
pub(crate) fn heir<'a>(
    leaders: &'a [String],
    dead: &str,
    alive: &BTreeSet<String>,
) -> Option<&'a str> {
    heir_in_turn(leaders, dead, alive, 0)
}

/// Whose turn it is to adopt `dead` after `turn` turns passed without an
/// adoption: the heir first, then the live roles after it in order,
/// cyclically. A process that never saw the role's token (it started
/// after the role was lost) does not know to adopt it; in the next turn
/// the next in line does.
pub(crate) fn heir_in_turn<'a>(
    leaders: &'a [String],
    dead: &str,
    alive: &BTreeSet<String>,
    turn: usize,
) -> Option<&'a str> {
    let at = leaders.iter().position(|l| l == dead)?;
    let live: Vec<&String> = (1..leaders.len())
        .map(|k| &leaders[(at + k) % leaders.len()])
        .filter(|l| alive.contains(*l))
        .collect();
    (!live.is_empty()).then(|| live[turn % live.len()].as_str())
}

/// The turns that passed for a role lost `waited` ago with a takeover time
/// of `patience`: each lasts `patience`, the first begins once the role
/// has been lost for `patience`.
fn turns_passed(waited: Duration, patience: Duration) -> usize {
    if patience.is_zero() {
        return 0;
    }
    (waited.as_secs_f64() / patience.as_secs_f64())
        .floor()
        .max(1.0) as usize
        - 1
}

/// The roles this process hosts, each an actor with its own stop signal.
struct Hosted<'a> {
    session: &'a Session,
    config: &'a HostConfig,
    tasks: JoinSet<(String, Result<(), RunError>)>,
    roles: BTreeSet<String>,
    /// One stop signal per hosted role: a role is handed back alone.
    stops: HashMap<String, watch::Sender<bool>>,
    /// Each hosted role's standby, as its actor is told it.
    standbys: HashMap<String, watch::Sender<Option<String>>>,
    /// With voters: the map, the claims, the lease.
    claims: Option<Claims>,
    /// The epoch each hosted role runs at (0 without voters).
    epochs: HashMap<String, u64>,
    /// Roles being handed home: released to the voters once stopped.
    handing_back: BTreeSet<String>,
    /// Roles released to the voters, until the map shows them released:
    /// not taken up again as roles the map gives this process.
    released: BTreeSet<String>,
    /// Roles handed back whose own process said it keeps their state:
    /// their journal here is stale once they are gone.
    copied_home: BTreeSet<String>,
    /// Roles stopped because the map gave them to another, or the lease
    /// lapsed (warned once each).
    superseded: BTreeSet<String>,
    /// When the roles here first ran (the lease counts from it until the
    /// map is first read).
    since: Instant,
    /// When the map was last read at a sweep.
    map_read: Option<Instant>,
    /// Processes standing by for their own roles (their home tokens).
    homes: BTreeSet<String>,
    /// Roles adopted here whose process is back, since when: their
    /// standby is that process until it says it keeps their snapshot,
    /// then they are stopped and handed home.
    sending_home: HashMap<String, Instant>,
    /// Roles going home whose process is late keeping their state
    /// (warned once each).
    home_late: BTreeSet<String>,
}

impl Hosted<'_> {
    /// Starts hosting `role` here (`adopted`: from a process gone for
    /// good, or taken back) at `epoch` (what the voters gave; 0 without).
    fn host(&mut self, role: &str, adopted: bool, epoch: u64) {
        if self.roles.contains(role) {
            // One actor per role: a second would find the journal locked,
            // and its end would orphan the first.
            tracing::warn!(process = %self.config.name, role, epoch, "the role runs here already");
            return;
        }
        if let (Some(_), Some(dir)) = (&self.claims, &self.config.state_dir) {
            if let Err(e) = standby::stamp_epoch(dir, role, epoch) {
                tracing::error!(process = %self.config.name, role, epoch, error = %e,
                    "cannot note the epoch the role runs at: a later adoption here will not trust its journal");
            }
        }
        self.epochs.insert(role.to_string(), epoch);
        self.superseded.remove(role);
        let (stop_tx, mut stop_rx) = watch::channel(false);
        self.stops.insert(role.to_string(), stop_tx);
        let stop = async move {
            let _ = stop_rx.wait_for(|s| *s).await;
        };
        let standby = self.config.standbys().then(|| {
            let (tx, rx) = watch::channel(None);
            self.standbys.insert(role.to_string(), tx);
            rx
        });
        let role_config = self.config.role(role, adopted, epoch, standby);
        let session = self.session.clone();
        let owned = role.to_string();
        self.tasks.spawn(async move {
            let result = driver::run(session, role_config, stop).await;
            (owned, result)
        });
        self.roles.insert(role.to_string());
    }

    /// Tells every hosted role its standby: the role that would inherit it
    /// among the live ones other than this process's (which die with it).
    fn tell_standbys(&self, alive: &BTreeSet<String>) {
        let others: BTreeSet<String> = alive.difference(&self.roles).cloned().collect();
        for (role, tx) in &self.standbys {
            // A role going home sends its state to its own process.
            let next = match self.sending_home.contains_key(role) {
                true => Some(role.clone()),
                false => heir(&self.config.leaders, role, &others).map(str::to_owned),
            };
            tx.send_if_modified(|now| {
                let changed = *now != next;
                now.clone_from(&next);
                changed
            });
        }
    }

    /// A role's actor ended: it is no longer hosted here.
    fn ended(&mut self, role: &str) {
        self.roles.remove(role);
        self.stops.remove(role);
        self.standbys.remove(role);
        self.epochs.remove(role);
    }

    /// Stops `role` to hand it back to its own process (released to the
    /// voters once its actor has ended).
    fn hand_back(&mut self, role: String) {
        self.stop(&role);
        self.handing_back.insert(role);
    }

    /// Stops the actor of `role` (it syncs its journal, then drops the
    /// role's token).
    fn stop(&self, role: &str) {
        if let Some(stop) = self.stops.get(role) {
            let _ = stop.send(true);
        }
    }
}

/// What this process has seen of the leader roles' tokens.
#[derive(Default)]
struct Tokens {
    alive: BTreeSet<String>,
    /// Roles seen up and then lost, since when. A role never seen up is
    /// still starting, not dead.
    lost: HashMap<String, Instant>,
    /// Lost roles found still held by their process (warned once per loss).
    fenced: BTreeSet<String>,
    /// With voters: each lost role's epoch in the map when its token went.
    /// A role whose epoch has moved since changed hands meanwhile (claimed
    /// by its process coming home, whose token is not up yet): it is not
    /// lost, and a takeover would fence off a holder just starting.
    lost_epochs: HashMap<String, u64>,
    /// Each role's newest durable mark heard (by epoch, then batch and
    /// position): the sensor and the peers have forgotten what lies
    /// before it, so a role started from a state behind it waits for
    /// inputs gone for good.
    published: HashMap<String, Durable>,
    /// Lost roles this process declined to adopt, its state of them being
    /// behind their mark (warned once per loss).
    declined: BTreeSet<String>,
    /// A mark heard since `published` was last kept on disk.
    unkept: bool,
    /// The roles this process heard marks of before it started, and finds
    /// without a token once started, were presumed lost (once).
    presumed: bool,
}

impl Tokens {
    /// A role's durable mark heard: kept if newer than the one kept.
    fn note_published(&mut self, bytes: &[u8]) {
        let Ok(mark) = decode::<Durable>(bytes) else {
            return;
        };
        let newer = self.published.get(&mark.leader).is_none_or(|kept| {
            (mark.epoch, mark.batch, mark.position) > (kept.epoch, kept.batch, kept.position)
        });
        if newer {
            self.published.insert(mark.leader.clone(), mark);
            self.unkept = true;
        }
    }

    /// The marks heard, kept in `dir` (at most once a sweep): see
    /// [`standby::keep_marks`].
    fn keep_published(&mut self, config: &HostConfig) {
        let (true, Some(dir)) = (self.unkept, &config.state_dir) else {
            return;
        };
        self.unkept = false;
        if let Err(e) = standby::keep_marks(dir, self.published.values()) {
            tracing::warn!(process = %config.name, error = %e, "could not keep the durable marks heard");
        }
    }

    /// Once, a moment after the start (the tokens up then have been
    /// heard): every role this process knows ran — it heard a durable
    /// mark of it before it started, or keeps a standby copy of it — that
    /// has no token now, nor runs here, is lost since `started`. A process
    /// never sees the token of a role lost while it was down go away, and
    /// would otherwise never adopt it in its turn (and with its standby
    /// copy, it may be the only one that can).
    fn presume_lost(&mut self, config: &HostConfig, hosted: &BTreeSet<String>, started: Instant) {
        if self.presumed || started.elapsed() < PRESUME_AFTER {
            return;
        }
        self.presumed = true;
        let own = config.name.as_str();
        let copied = config.leaders.iter().filter(|r| {
            config
                .state_dir
                .as_ref()
                .is_some_and(|dir| standby::standby_path(dir, r).exists())
        });
        let known: BTreeSet<&String> = self.published.keys().chain(copied).collect();
        let gone: Vec<String> = known
            .into_iter()
            .filter(|r| {
                !self.alive.contains(*r)
                    && !hosted.contains(*r)
                    && r.as_str() != own
                    && !self.lost.contains_key(*r)
            })
            .cloned()
            .collect();
        for role in gone {
            tracing::info!(%role, "a role heard of before the start has no token: presumed lost");
            self.lost.insert(role, started);
        }
    }

    /// The marks this process kept before it was started again.
    fn heard_before(config: &HostConfig) -> Self {
        let mut tokens = Tokens::default();
        let Some(dir) = &config.state_dir else {
            return tokens;
        };
        match standby::heard_marks(dir) {
            Ok(marks) => {
                for mark in marks {
                    tokens.published.insert(mark.leader.clone(), mark);
                }
            }
            Err(e) => tracing::warn!(process = %config.name, error = %e,
                "the durable marks heard before cannot be read: only those heard from now on count"),
        }
        tokens
    }
}

/// How long after its start a process presumes lost the roles it heard
/// of before and finds without a token ([`Tokens::presume_lost`]).
const PRESUME_AFTER: Duration = Duration::from_secs(1);

/// Runs this process's roles until `shutdown`.
pub async fn run(
    session: Session,
    config: HostConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), RunError> {
    let keys = &config.keys;
    let mut hosted = Hosted {
        session: &session,
        config: &config,
        tasks: JoinSet::new(),
        roles: BTreeSet::new(),
        stops: HashMap::new(),
        standbys: HashMap::new(),
        claims: config
            .lease
            .map(|lease| Claims::new(session.clone(), keys.clone(), &config.name, lease)),
        epochs: HashMap::new(),
        handing_back: BTreeSet::new(),
        copied_home: BTreeSet::new(),
        released: BTreeSet::new(),
        superseded: BTreeSet::new(),
        since: Instant::now(),
        map_read: None,
        homes: BTreeSet::new(),
        sending_home: HashMap::new(),
        home_late: BTreeSet::new(),
    };

    // Standing by for its own role: the token that asks for it back.
    let mut home: Option<zenoh::liveliness::LivelinessToken> = None;
    if hosted.claims.is_some() {
        // The voters decide: the sweep claims the role (and stands by
        // for it if another holds it).
    } else if hosted_elsewhere(&session, keys, &config.name).await {
        tracing::warn!(process = %config.name, "its role is hosted by another process (adopted while this one was away, or its old token not yet expired); standing by and asking for it back");
        home = Some(declare_home(&session, keys, &config.name).await?);
    } else {
        hosted.host(&config.name, false, 0);
    }
    let Heard {
        homes,
        token_samples,
        copies_home,
        stored,
        durable,
        copies_asked,
    } = Heard::declare(&session, &config).await?;
    let mut tokens = Tokens::heard_before(&config);
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    let standing = Instant::now();
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            sample = token_samples.recv_async() => {
                let Ok(sample) = sample else { break };
                on_token(&sample, &mut hosted, &mut tokens, &mut home);
            }
            sample = homes.recv_async() => {
                let Ok(sample) = sample else { break };
                let Some(role) = Keys::chunk(sample.key_expr().as_str(), 0) else { continue };
                on_home(&mut hosted, role, sample.kind());
            }
            sample = copies_home.recv_async() => {
                let Ok(sample) = sample else { break };
                if home.is_some() {
                    keep_copy_home(&hosted, &sample.payload().to_bytes()).await;
                }
            }
            sample = stored.recv_async() => {
                let Ok(sample) = sample else { break };
                on_stored(&mut hosted, &sample.payload().to_bytes());
            }
            sample = durable.recv_async() => {
                let Ok(sample) = sample else { break };
                tokens.note_published(&sample.payload().to_bytes());
            }
            query = copies_asked.recv_async() => {
                let Ok(query) = query else { break };
                copies::answer(&config, &query).await;
            }
            done = hosted.tasks.join_next(), if !hosted.tasks.is_empty() => {
                if let Some(Ok((role, result))) = done {
                    on_ended(&mut hosted, &role, result, &mut home).await?;
                }
            }
            _ = tick.tick() => {
                on_tick(&mut hosted, &mut tokens, &mut home, standing).await?;
                tokens.keep_published(hosted.config);
            }
        }
        hosted.tell_standbys(&tokens.alive);
    }
    for role in &hosted.roles {
        hosted.stop(role);
    }
    drop(home);
    while let Some(done) = hosted.tasks.join_next().await {
        if let Ok((role, Err(e))) = done {
            tracing::error!(process = %config.name, role = %role, error = %e, "role failed");
        }
    }
    Ok(())
}

/// The host's sweep: the leases (with voters), its own role taken back
/// when free, lost roles adopted, roles going home handed back.
async fn on_tick(
    hosted: &mut Hosted<'_>,
    tokens: &mut Tokens,
    home: &mut Option<zenoh::liveliness::LivelinessToken>,
    standing: Instant,
) -> Result<(), RunError> {
    let config = hosted.config;
    if hosted.claims.is_some() {
        keep_leases(hosted, home).await?;
    }
    // Standing by, and the role's token went away before the subscriber
    // was there to see it go: take it all the same.
    if hosted.claims.is_none()
        && home.is_some()
        && !tokens.alive.contains(&config.name)
        && !hosted.roles.contains(&config.name)
        && standing.elapsed() > Duration::from_secs(1)
        && !hosted_elsewhere(hosted.session, &config.keys, &config.name).await
        && config.journal_holder(&config.name).is_none()
    {
        tracing::warn!(process = %config.name, "its role is free: taking it back");
        *home = None;
        return_from(config, None);
        hosted.host(&config.name, true, 0);
    }
    if let Some(patience) = config.takeover_after {
        tokens.presume_lost(config, &hosted.roles, standing);
        adopt_lost_roles(hosted, tokens, patience).await;
    }
    hand_home_unanswered(hosted);
    Ok(())
}

/// What the host listens to beside its roles' actors.
struct Heard {
    /// Processes standing by for their own roles.
    homes: Samples,
    /// The leader roles' tokens.
    token_samples: Samples,
    /// Going home over the network: the copies of this process's own role
    /// sent here while it stands by ...
    copies_home: Samples,
    /// ... and every standby's word that it keeps a copy (a role adopted
    /// here waits for its process's).
    stored: Samples,
    /// Every role's durable marks: an adoption must not start behind the
    /// last one.
    durable: Samples,
    /// Adopters asking for the standby copies this process keeps.
    copies_asked: copies::Asked,
}

type Samples =
    zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>;

impl Heard {
    async fn declare(session: &Session, config: &HostConfig) -> Result<Heard, MeshError> {
        let keys = &config.keys;
        let liveliness = |key: String, what: &'static str| async move {
            session
                .liveliness()
                .declare_subscriber(key)
                .history(true)
                .await
                .map_err(|e| MeshError::new(what, e))
        };
        let plain = |key: String, what: &'static str| async move {
            session
                .declare_subscriber(key)
                .await
                .map_err(|e| MeshError::new(what, e))
        };
        Ok(Heard {
            homes: liveliness(
                keys.alive_role("home"),
                "declare the home liveliness subscriber",
            )
            .await?,
            token_samples: liveliness(
                keys.alive_role("leader"),
                "declare the leader liveliness subscriber",
            )
            .await?,
            copies_home: plain(
                keys.leader_standby(&config.name),
                "declare the home-copy subscriber",
            )
            .await?,
            stored: plain(
                keys.leader_stored("*"),
                "declare the standby-acknowledgement subscriber",
            )
            .await?,
            durable: plain(
                keys.every_leader_durable(),
                "declare the durable-mark subscriber",
            )
            .await?,
            copies_asked: copies::declare(session, config)
                .await
                .map_err(|e| MeshError::new("declare the standby-copy queryable", e))?,
        })
    }
}

/// A role's actor ended (stopped, handed back, or failed): released to
/// the voters if it was handed back; its own role held elsewhere, with
/// no token to say so (a partition at start), makes this process stand
/// by for it.
async fn on_ended(
    hosted: &mut Hosted<'_>,
    role: &str,
    result: Result<(), RunError>,
    home: &mut Option<zenoh::liveliness::LivelinessToken>,
) -> Result<(), RunError> {
    let config = hosted.config;
    hosted.ended(role);
    let copied_home = hosted.copied_home.remove(role);
    if hosted.handing_back.remove(role) {
        if let Some(claims) = &hosted.claims {
            // Before the release: the home process claims the role only
            // once it is released, so it installs the copy it kept after
            // this journal is gone, even on a shared disk.
            if copied_home {
                forget_handed_back(config, role);
            }
            claims.release(role).await;
            hosted.released.insert(role.to_string());
        }
    }
    match result {
        Ok(()) => tracing::info!(process = %config.name, role, "role stopped"),
        Err(RunError::Journal(JournalError::Ownership(OwnershipError::Held {
            holder, ..
        }))) if role == config.name => {
            tracing::warn!(process = %config.name, %holder, "its role is held by another process; standing by and asking for it back");
            if home.is_none() {
                *home = Some(declare_home(hosted.session, &config.keys, &config.name).await?);
            }
        }
        Err(e) => tracing::error!(process = %config.name, role, error = %e, "role failed"),
    }
    Ok(())
}

/// A leader role's token came or went. Its own role free again while
/// standing by for it is taken back at once; another role lost starts
/// its wait for adoption.
fn on_token(
    sample: &zenoh::sample::Sample,
    hosted: &mut Hosted<'_>,
    tokens: &mut Tokens,
    home: &mut Option<zenoh::liveliness::LivelinessToken>,
) {
    let config = hosted.config;
    let Some(role) = Keys::chunk(sample.key_expr().as_str(), 0) else {
        return;
    };
    let role = role.to_string();
    match sample.kind() {
        SampleKind::Put => {
            tokens.lost.remove(&role);
            tokens.fenced.remove(&role);
            tokens.alive.insert(role);
        }
        SampleKind::Delete => {
            // Not a warning by itself: every role drops its token when
            // the deployment stops. A loss that lasts is warned about
            // when the role is adopted.
            tracing::info!(process = %config.name, role = %role, "leader role lost its token");
            tokens.alive.remove(&role);
            if role == config.name
                && home.is_some()
                && !hosted.roles.contains(&role)
                && hosted.claims.is_none()
            {
                // Its own role is free (handed back, or the old
                // token expired): take it now, takeover or not.
                tracing::warn!(process = %config.name, "its role is free again: taking it back");
                *home = None;
                return_from(config, None);
                hosted.host(&role, true, 0);
            } else if !hosted.roles.contains(&role) {
                if let Some(claims) = &hosted.claims {
                    tokens
                        .lost_epochs
                        .insert(role.clone(), claims.last_epoch(&role));
                }
                tokens.lost.insert(role, Instant::now());
            }
        }
    }
}

/// Adopts the roles lost for `patience` or longer whose heir is this
/// process, unless another process still hosts them or holds their
/// journal (then they are looked at again later).
async fn adopt_lost_roles(hosted: &mut Hosted<'_>, tokens: &mut Tokens, patience: Duration) {
    let config = hosted.config;
    let due: Vec<String> = tokens
        .lost
        .iter()
        .filter(|(_, since)| since.elapsed() >= patience)
        .map(|(role, _)| role.clone())
        .collect();
    for role in due {
        if hosted.roles.contains(&role) || role == config.name {
            // Run here since its token went (taken up again, or back
            // home), or this process's own role, which it claims or takes
            // back itself: never adopted as another's.
            tokens.lost.remove(&role);
            continue;
        }
        let live: BTreeSet<String> = tokens.alive.union(&hosted.roles).cloned().collect();
        let waited = tokens.lost.get(&role).map_or(patience, Instant::elapsed);
        let turn = turns_passed(waited, patience);
        let Some(heir) = heir_in_turn(&config.leaders, &role, &live, turn) else {
            continue;
        };
        if !hosted.roles.contains(heir) {
            // Another process adopts it (or, its home, takes it back).
            // Looked at again while its token stays gone: that process may
            // be lost before it does (a role handed home, then its home
            // host lost), and then the heir is another; or it may never
            // have seen the role's token (started after the loss), and
            // then the next turn is another's.
            continue;
        }
        tokens.lost.remove(&role);
        if config.state_dir.is_none() {
            tracing::error!(process = %config.name, role = %role,
                "cannot adopt: no state_dir, the role's state is lost; its answers stay missing");
            continue;
        }
        if hosted_elsewhere(hosted.session, &config.keys, &role).await {
            continue;
        }
        if hosted.claims.is_some() {
            adopt_by_claim(hosted, tokens, &role, patience).await;
            continue;
        }
        // Another process may keep a newer copy of the role than this
        // one (the heir changed since the role's last snapshot went out).
        copies::take_newest(hosted.session, config, &role, None).await;
        if let Some(holder) = config.journal_holder(&role) {
            // Its process is alive, only out of reach: the
            // role stays with it; look again later.
            if tokens.fenced.insert(role.clone()) {
                tracing::warn!(process = %config.name, role = %role, %holder,
                    "not adopting: the role's journal is still held (its process runs, cut off); its answers stay missing until it is back");
            }
            tokens.lost.insert(role, Instant::now());
            continue;
        }
        tracing::warn!(process = %config.name, role = %role, "adopting a leader role gone for good");
        adopt_from(config, &role, None);
        hosted.host(&role, true, 0);
    }
}

/// Adopts `role` if the voters commit this process's claim on it, fencing
/// off the epoch of the holder the map names; another claimant that won,
/// or a holder still there, leaves it alone (looked at again if its token
/// stays gone).
async fn adopt_by_claim(
    hosted: &mut Hosted<'_>,
    tokens: &mut Tokens,
    role: &str,
    patience: Duration,
) {
    let config = hosted.config;
    let Some(claims) = hosted.claims.as_mut() else {
        return;
    };
    let Some(map) = claims.read().await.cloned() else {
        // No voter leads: nothing can be decided now; try again later.
        tokens.lost.insert(role.to_string(), Instant::now());
        return;
    };
    let now = map.get(role).map_or(0, |e| e.epoch);
    let seen = tokens.lost_epochs.insert(role.to_string(), now);
    if seen.is_some_and(|seen| seen != now) {
        // Claimed since its token went: wait for the new holder's token.
        tokens.lost.insert(role.to_string(), Instant::now());
        return;
    }
    copies::take_newest(hosted.session, config, role, Some(now)).await;
    if let Some(behind) = behind_published(config, tokens, role, now) {
        // Another process holds a newer copy (the role's standby, cut off
        // or slow to show its token now): it adopts the role once it is
        // heir again. Adopted from here, the role would wait for ever.
        if tokens.declined.insert(role.to_string()) {
            tracing::warn!(process = %config.name, role, %behind,
                "not adopting: this process's state of the role is behind the role's last durable mark; waiting for a process that holds a newer one");
        }
        tokens.lost.insert(role.to_string(), Instant::now());
        return;
    }
    tokens.declined.remove(role);
    match claims
        .claim(
            role,
            claims::fencing(&map, role),
            patience.max(CLAIM_PATIENCE),
        )
        .await
    {
        Claimed::Won(epoch) => {
            tracing::warn!(process = %config.name, role, epoch, "adopting a leader role gone for good: the voters gave it here");
            adopt_from(config, role, Some(now));
            hosted.host(role, true, epoch);
        }
        Claimed::Lost { holder, epoch } => {
            tracing::info!(process = %config.name, role, %holder, epoch, "not adopting: the voters gave the role to another");
        }
        Claimed::Undecided => {
            tracing::warn!(process = %config.name, role, "not adopting yet: the voters did not decide");
            tokens.lost.insert(role.to_string(), Instant::now());
        }
    }
}

/// Why this process's state of `role` is behind the role's last durable
/// mark heard (None: it is not, or no mark was heard): what an adoption
/// here would start from, with the role's epoch `last` in the map.
fn behind_published(config: &HostConfig, tokens: &Tokens, role: &str, last: u64) -> Option<String> {
    let dir = config.state_dir.as_ref()?;
    let published = tokens.published.get(role)?;
    let from = match standby::adoption_source(dir, role, last) {
        Ok(Source::Journal) => return None,
        Ok(Source::StandbyCopy(mark)) => mark,
        Ok(Source::Nothing) | Err(_) => Durable {
            batch: 0,
            position: 0,
            ..published.clone()
        },
    };
    standby::behind(&from, published).then(|| {
        format!(
            "its copy at batch {} and position {}, the mark at batch {} and position {}",
            from.batch, from.position, published.batch, published.position
        )
    })
}

/// How long a claim may wait for the voters to decide.
const CLAIM_PATIENCE: Duration = Duration::from_secs(5);

/// How often the map is read to keep the leases.
const MAP_EVERY: Duration = Duration::from_secs(1);

/// With voters, at a sweep (at most every [`MAP_EVERY`]): reads the map,
/// stops every role it gives to another (or every role, if no voter has
/// led for the lease), and claims this process's own role when it runs
/// nowhere (else stands by for it, asking for it back).
async fn keep_leases(
    hosted: &mut Hosted<'_>,
    home: &mut Option<zenoh::liveliness::LivelinessToken>,
) -> Result<(), RunError> {
    let config = hosted.config;
    if hosted.map_read.is_some_and(|at| at.elapsed() < MAP_EVERY) {
        return Ok(());
    }
    hosted.map_read = Some(Instant::now());
    let since = hosted.since;
    let Some(claims) = hosted.claims.as_mut() else {
        return Ok(());
    };
    let (map, lapsed, lease) = (
        claims.read().await.cloned(),
        claims.lapsed(since),
        claims.lease,
    );
    let Some(map) = map else {
        if lapsed {
            for role in hosted.roles.clone() {
                if hosted.superseded.insert(role.clone()) {
                    tracing::error!(process = %config.name, %role, ?lease,
                        "no voter has led for the lease: stopping the role (its answers are missing) until a majority is back");
                }
                hosted.stop(&role);
            }
        }
        return Ok(());
    };
    for role in hosted.roles.clone() {
        let epoch = hosted.epochs.get(&role).copied().unwrap_or(0);
        if let Verdict::Superseded { holder, epoch: now } =
            claims::verdict(&map, &role, &config.name, epoch)
        {
            if hosted.superseded.insert(role.clone()) && !hosted.handing_back.contains(&role) {
                tracing::warn!(process = %config.name, %role, held_at = epoch, ?holder, epoch = now,
                    "the voters gave the role to another (this process was cut off): stopping it");
            }
            hosted.stop(&role);
        }
    }
    take_up_held_roles(hosted, &map).await;
    let own = &config.name;
    if hosted.roles.contains(own) {
        return Ok(());
    }
    match map.get(own).and_then(|e| e.holder.clone()) {
        Some(holder) if holder != *own => {
            // Adopted elsewhere: stand by, asking for it back.
            if home.is_none() {
                tracing::warn!(process = %own, %holder, "its role is held by another process; standing by and asking for it back");
                *home = Some(declare_home(hosted.session, &config.keys, own).await?);
            }
        }
        _ => {
            let Some(claims) = hosted.claims.as_mut() else {
                return Ok(());
            };
            let fencing = claims::fencing(&map, own);
            let last = map.get(own).map_or(0, |e| e.epoch);
            match claims.claim(own, fencing, CLAIM_PATIENCE).await {
                Claimed::Won(epoch) => {
                    tracing::info!(process = %own, epoch, "the voters gave this process its role");
                    let back = home.take().is_some() || epoch > 1;
                    if back {
                        return_from(config, Some(last));
                    }
                    hosted.host(own, back, epoch);
                }
                Claimed::Lost { holder, epoch } => {
                    tracing::warn!(process = %own, %holder, epoch, "its role went to another process");
                }
                Claimed::Undecided => {
                    tracing::warn!(process = %own, "the voters did not decide its claim; claiming again");
                }
            }
        }
    }
    Ok(())
}

/// A process's home token came or went. A role adopted here whose
/// process is back goes home: with standbys, its standby becomes that
/// process, and once that process keeps its snapshot the role stops here
/// ([`on_stored`]); without, it stops at once (the process finds its
/// journal on the shared disk). Stopping the actor syncs its journal,
/// then drops the role's token, which the home process waits for.
fn on_home(hosted: &mut Hosted<'_>, role: &str, kind: SampleKind) {
    let config = hosted.config;
    if kind == SampleKind::Delete {
        hosted.homes.remove(role);
        hosted.sending_home.remove(role);
        hosted.home_late.remove(role);
        return;
    }
    hosted.homes.insert(role.to_string());
    if role == config.name || !hosted.roles.contains(role) {
        return;
    }
    if config.standbys() {
        tracing::warn!(process = %config.name, role, "its process is back: sending it the role's state, then handing the role back");
        hosted.sending_home.insert(role.to_string(), Instant::now());
    } else {
        tracing::warn!(process = %config.name, role, "its process is back: handing the role back");
        hosted.hand_back(role.to_string());
    }
}

/// A standby's word that it keeps a role's snapshot: the word of a role's
/// own process, for a role going home from here, hands the role back.
fn on_stored(hosted: &mut Hosted<'_>, bytes: &[u8]) {
    let Ok(stored) = decode::<StandbyStored>(bytes) else {
        return;
    };
    if stored.host != stored.role || hosted.sending_home.remove(&stored.role).is_none() {
        return;
    }
    tracing::warn!(process = %hosted.config.name, role = %stored.role, batch = stored.mark.batch,
        "its process keeps the role's state: handing the role back");
    hosted.home_late.remove(&stored.role);
    hosted.copied_home.insert(stored.role.clone());
    hosted.hand_back(stored.role);
}

/// After handing `role` home to a process that keeps its state: the
/// role's journal and snapshot this process wrote while it ran the role
/// stop where the role left, and the sensor forgets what follows as the
/// role moves on. Left here, a later adoption would start from them
/// (a journal is preferred to a standby copy) and wait for batches gone
/// for good; removed, it starts from the standby copy. On a shared disk
/// the home process starts from the copy it acknowledged all the same.
fn forget_handed_back(config: &HostConfig, role: &str) {
    let Some(dir) = &config.state_dir else {
        return;
    };
    if let Err(e) = standby::forget_journal(dir, role) {
        tracing::warn!(process = %config.name, role, error = %e,
            "could not remove the journal of a role handed home");
    }
}

/// How long a role going home waits for its process to keep its state
/// before it is handed back all the same (without voters: that process
/// then rebuilds what it can from its own journal) or, with voters, the
/// wait is warned about.
const HOME_PATIENCE: Duration = Duration::from_secs(15);

/// The roles whose process did not say it keeps their state within
/// [`HOME_PATIENCE`]. Without voters they are handed back all the same.
/// With voters they stay here, still sending their state home, and the
/// wait is warned about once: that process's own journal stopped when
/// the role left it, and it will not use it (see
/// [`standby::forget_stale_journal`]), so handing the role back without a
/// copy would leave the role with no state to start from.
fn hand_home_unanswered(hosted: &mut Hosted<'_>) {
    let late: Vec<String> = hosted
        .sending_home
        .iter()
        .filter(|(_, since)| since.elapsed() > HOME_PATIENCE)
        .map(|(role, _)| role.clone())
        .collect();
    for role in late {
        if hosted.claims.is_some() {
            if hosted.home_late.insert(role.clone()) {
                tracing::warn!(process = %hosted.config.name, %role,
                    "its process has not kept the role's state yet: the role stays here, sending it");
            }
            continue;
        }
        tracing::warn!(process = %hosted.config.name, %role, "its process did not keep the role's state in time: handing the role back all the same");
        hosted.sending_home.remove(&role);
        hosted.hand_back(role);
    }
}

/// Standing by for its own role: the role's snapshot, sent here by the
/// process running it, kept on this disk and acknowledged; the role
/// starts from it when it comes home ([`return_from`]).
async fn keep_copy_home(hosted: &Hosted<'_>, bytes: &[u8]) {
    let config = hosted.config;
    let Some(dir) = &config.state_dir else {
        return;
    };
    let copy = match decode::<StandbyCopy>(bytes) {
        Ok(copy) if copy.role == config.name => copy,
        Ok(_) => return,
        Err(e) => {
            tracing::warn!(process = %config.name, error = %e, "a copy of its role refused");
            return;
        }
    };
    match standby::keep(dir, &copy, &config.name) {
        Ok(stored) => {
            let key = config.keys.leader_stored(&config.name);
            if let Err(e) = hosted.session.put(key, encode(&stored)).await {
                tracing::warn!(process = %config.name, error = %e, "could not acknowledge the copy of its role");
            }
        }
        Err(e) => {
            tracing::error!(process = %config.name, error = %e, "cannot keep the copy of its role")
        }
    }
}

/// Before taking its own role back home: the copy the role's last holder
/// sent here, if any, replaces the journal the role left; with voters
/// (`last`: the role's epoch before this claim), a journal of an earlier
/// holding is not used in any case. Says which at info.
fn return_from(config: &HostConfig, last: Option<u64>) {
    let Some(dir) = &config.state_dir else {
        return;
    };
    forget_stale(config, dir, &config.name, last);
    match standby::prepare_return(dir, &config.name) {
        Ok(Source::StandbyCopy(mark)) => {
            tracing::info!(process = %config.name, batch = mark.batch, position = mark.position,
                "taking its role back from the state its last holder sent here")
        }
        Ok(_) => {
            tracing::info!(process = %config.name, "taking its role back from its own journal")
        }
        Err(e) => tracing::error!(process = %config.name, error = %e,
            "the copy its last holder sent cannot be used: the role starts from its own journal"),
    }
}

/// Takes up every role besides its own that the map gives this process
/// and that it does not run: it restarted while holding them, or
/// stopped them when its lease lapsed. Nobody else would adopt them (the
/// map names a live holder), so their answers would stay missing.
async fn take_up_held_roles(hosted: &mut Hosted<'_>, map: &idmesh_consensus::RolesAnswer) {
    let config = hosted.config;
    let mine = |role: &str| {
        map.get(role)
            .is_some_and(|e| e.holder.as_deref() == Some(config.name.as_str()))
    };
    hosted.released.retain(|role| mine(role));
    let held: Vec<(String, u64)> = map
        .roles
        .iter()
        .filter(|e| e.role != config.name && mine(&e.role))
        .filter(|e| !hosted.roles.contains(&e.role) && !hosted.released.contains(&e.role))
        .map(|e| (e.role.clone(), e.epoch))
        .collect();
    for (role, epoch) in held {
        tracing::warn!(process = %config.name, %role, epoch,
            "the voters give this process a role it does not run: taking it up again");
        // Its copy may be older than another process's (the role went
        // home, and its home keeps the state it was sent).
        copies::take_newest(hosted.session, config, &role, Some(epoch)).await;
        adopt_from(config, &role, Some(epoch));
        hosted.host(&role, true, epoch);
    }
}

/// Before adopting `role`: its journal in this state directory if there
/// is one (a shared disk, or this process held the role last: `last` is
/// the role's epoch before this holding, with voters), else the standby
/// copy this process kept, installed as the role's snapshot. Says which
/// at info.
fn adopt_from(config: &HostConfig, role: &str, last: Option<u64>) {
    let Some(dir) = &config.state_dir else {
        return;
    };
    forget_stale(config, dir, role, last);
    match standby::prepare_adoption(dir, role) {
        Ok(Source::Journal) => {
            tracing::info!(process = %config.name, role, "adopting from the role's own journal")
        }
        Ok(Source::StandbyCopy(mark)) => {
            tracing::info!(process = %config.name, role, batch = mark.batch, position = mark.position,
                "adopting from this process's standby copy of the role's snapshot")
        }
        Ok(Source::Nothing) => {
            tracing::warn!(process = %config.name, role,
                "no journal of the role and no standby copy here: it is rebuilt from the stream's beginning, if the sensor still holds it")
        }
        Err(e) => {
            tracing::error!(process = %config.name, role, error = %e,
                "the standby copy cannot be used: the role is rebuilt from the stream's beginning, if the sensor still holds it")
        }
    }
}

/// With voters: removes this process's journal of `role` if it was
/// written in an earlier holding than the last (`last`), which the role's
/// holders since have left behind (see [`standby::forget_stale_journal`]).
fn forget_stale(config: &HostConfig, dir: &std::path::Path, role: &str, last: Option<u64>) {
    let Some(last) = last else {
        return;
    };
    match standby::forget_stale_journal(dir, role, last) {
        Ok(Some(written)) => tracing::warn!(process = %config.name, role, written, last,
            "this process's journal of the role is of an earlier holding: not used"),
        Ok(None) => {}
        Err(e) => tracing::error!(process = %config.name, role, error = %e,
            "cannot remove a journal of an earlier holding of the role"),
    }
}

/// The token of a process standing by for its own role `name`.
async fn declare_home(
    session: &Session,
    keys: &Keys,
    name: &str,
) -> Result<zenoh::liveliness::LivelinessToken, MeshError> {
    session
        .liveliness()
        .declare_token(keys.alive("home", name))
        .await
        .map_err(|e| MeshError::new("declare the home liveliness token", e))
}

/// Whether some process holds `role`'s token now.
async fn hosted_elsewhere(session: &Session, keys: &Keys, role: &str) -> bool {
    let Ok(replies) = session
        .liveliness()
        .get(keys.alive("leader", role))
        .timeout(Duration::from_millis(500))
        .await
    else {
        return false;
    };
    let mut found = false;
    while let Ok(reply) = replies.recv_async().await {
        found |= reply.result().is_ok();
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_next_live_role_inherits_cyclically() {
        let leaders: Vec<String> = ["l0", "l1", "l2", "l3"].map(String::from).to_vec();
        let alive = |names: &[&str]| names.iter().map(|n| n.to_string()).collect();
        assert_eq!(
            heir(&leaders, "l1", &alive(&["l0", "l2", "l3"])),
            Some("l2")
        );
        assert_eq!(heir(&leaders, "l1", &alive(&["l0", "l3"])), Some("l3"));
        assert_eq!(heir(&leaders, "l3", &alive(&["l1", "l2"])), Some("l1"));
        assert_eq!(heir(&leaders, "l2", &alive(&[])), None);
        assert_eq!(heir(&leaders, "nobody", &alive(&["l0"])), None);
    }

    /// A role not adopted in its heir's turn passes to the next live role
    /// in line, and round again.
    #[test]
    fn each_turn_passes_the_adoption_to_the_next_in_line() {
        let leaders: Vec<String> = ["l0", "l1", "l2", "l3"].map(String::from).to_vec();
        let alive: BTreeSet<String> = ["l0", "l2", "l3"].map(String::from).into();
        let turn = |k| heir_in_turn(&leaders, "l1", &alive, k);
        assert_eq!(
            [turn(0), turn(1), turn(2), turn(3)],
            [Some("l2"), Some("l3"), Some("l0"), Some("l2")]
        );
        let second = Duration::from_secs(1);
        assert_eq!(turns_passed(second, second), 0, "the heir's turn");
        assert_eq!(turns_passed(Duration::from_millis(1999), second), 0);
        assert_eq!(turns_passed(2 * second, second), 1, "the next one's");
        assert_eq!(turns_passed(7 * second / 2, second), 2);
    }
}
