//! Sequencing and routing of the event stream.
//!
//! Every trace event becomes an item with the next global seq. The router
//! knows which leader surveils each track ([`Regions`]: cells fitted to the
//! crowd and redrawn as it moves, or fixed places), turns a change of
//! region into a `Handover`, stamps observations with the
//! observed track's mixing log (the sensor network's log of Section 5.4.2),
//! and sends each item to the leaders whose [`Interest`] it meets — routed
//! by key expression, one key per leader, never broadcast and filtered.
//! The log of every item is kept so that a leader that starts following a
//! track can be sent what it missed.

use crate::cuts::Wanted;
use idmesh_belief::{MixingLog, RadonShare};
use idmesh_placement::{Handover, PlacementError, RegionRule, Regions};
use idmesh_protocol::trace::{Header, Line};
use idmesh_protocol::wire::coordinator_to_sensor::SensorPositions;
use idmesh_protocol::wire::factored::FactoredStart;
use idmesh_protocol::wire::interest::Interest;
use idmesh_protocol::wire::leader_to_sensor::{Follow, Unfollow};
use idmesh_protocol::wire::sensor_to_leader::{Begin, Growth, Handed, Item, Sequenced, UNHELD};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LeaderPlace {
    pub name: String,
    /// Where the leader sits, under fixed places (tracks belong to the
    /// nearest leader). None for every leader: regions fitted to the crowd
    /// and redrawn as it moves (the default).
    pub at: Option<(f64, f64)>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RouterConfig {
    pub sensor: String,
    pub leaders: Vec<LeaderPlace>,
    pub distributed_rule: bool,
    pub budget: u32,
    /// OMP before thresholding (needs k known and a budget).
    pub omp: bool,
    /// The leaders hold the factored belief (None: the Radon belief).
    pub factored: Option<FactoredStart>,
    /// On an identity stream with a known start and the factored belief,
    /// the leaders hold the factored identity belief with groups of at
    /// most this many slots (`Begin::factored_identity`); None, or a
    /// stream without a known start: the information matrix's rows.
    pub factored_identity: Option<u32>,
    /// Where the stream's leading `move` lines place each track
    /// ([`idmesh_placement::leading_places`] of the trace the sensor
    /// streams): a track placed there starts with the leader nearest to it
    /// (in the Begin's owners) rather than with leader `track mod L`. Empty
    /// (a stream that is fed live) or None for a track: round robin.
    pub placed: Vec<Option<(f64, f64)>>,
    /// The region rule, when not the one the leaders' places imply (fixed
    /// places if they have them, else fitted cells): tests that want
    /// fitted cells redrawn within a short stream.
    pub regions: Option<RegionRule>,
}

#[derive(Debug, thiserror::Error)]
pub enum RouterError {
    #[error("a deployment needs at least one leader")]
    NoLeaders,
    #[error("request from leader index {0}, which does not exist")]
    UnknownLeader(u16),
    #[error("request names track {track}, but there are {tracks} tracks")]
    UnknownTrack { track: u32, tracks: u32 },
    #[error(
        "unfollow request on a stream whose leaders' interests only grow (Radon, or factored \
         without shrink_interest)"
    )]
    Unfollow,
    #[error("OMP at the leaders needs {0}")]
    Omp(&'static str),
    #[error(transparent)]
    Start(#[from] PlacementError),
    /// A stream the leaders would refuse at its Begin (say, an identity
    /// stream beyond their track limit): refused here, before anything is
    /// sent, rather than streamed to leaders that drop every batch.
    #[error("the stream cannot start: {0}")]
    Begin(String),
}

/// Serde: the gateway's snapshot holds it whole.
#[derive(Serialize, Deserialize)]
pub struct Router {
    config: RouterConfig,
    /// The stream's header: what ingested lines are checked against.
    #[serde(with = "idmesh_protocol::trace::as_json")]
    header: Header,
    begin: Begin,
    interests: Vec<Interest>,
    /// For each leader and track, the item after which the track last
    /// entered its interest (a handover to it, a follow request): an
    /// unfollow request decided before then is stale.
    followed_at: Vec<Vec<u64>>,
    /// Which leader surveils each track (shared with `idmesh replay`'s
    /// regional rule).
    regions: Regions,
    /// Each track's last `move` (the live map's positions query).
    positions: Vec<Option<[f64; 2]>>,
    mixing_log: MixingLog,
    seq: u64,
    events: u64,
    log: Vec<Sequenced>,
    /// On a factored stream whose interests shrink, the seqs of the logged
    /// items on each track: a follow there wants exactly the items on its
    /// tracks, and finds them here without a pass over the log (a crowd
    /// makes a follow at nearly every cross-leader mix, with the log as
    /// long as the slowest leader's lag).
    touching: Option<Vec<VecDeque<u64>>>,
    outbox: Vec<Vec<Sequenced>>,
}

impl Router {
    /// A router for a trace with this header; queues the `Begin` item.
    pub fn new(config: RouterConfig, header: &Header) -> Result<Self, RouterError> {
        let leaders = config.leaders.len();
        if leaders == 0 {
            return Err(RouterError::NoLeaders);
        }
        if config.omp && config.budget == 0 {
            return Err(RouterError::Omp(
                "a budget (it re-expresses what the budget drops)",
            ));
        }
        // OMP may put mass on φ_∅, which only leader 0 can hold when k is
        // unknown (every observation grows it).
        if config.omp && header.red_count().is_none() {
            return Err(RouterError::Omp(
                "k, the number of red targets, in the trace header",
            ));
        }
        let tracks = header.tracks;
        let places: Vec<_> = config.leaders.iter().map(|l| l.at).collect();
        let rule = if let Some(rule) = &config.regions {
            rule.clone()
        } else if places.iter().any(Option::is_some) {
            RegionRule::Fixed(places)
        } else {
            RegionRule::fitted()
        };
        let whole = (config.factored.as_ref()).is_some_and(|f| f.whole(tracks as u32, leaders));
        let mut regions = match whole {
            true => Regions::whole(tracks),
            false => Regions::starting(&rule, leaders, tracks, &config.placed),
        };
        // Only leaders that keep regional components take a mix's track.
        if !config.factored.as_ref().is_some_and(|f| f.regional) {
            regions = regions.keeping_mixes_across();
        }
        let begin = Begin {
            factored: config.factored,
            tracks: tracks as u32,
            red: header.red_count().map(|k| k as u32),
            initial_red: header.initial_red.clone(),
            leaders: config.leaders.iter().map(|l| l.name.clone()).collect(),
            owners: regions.owners().to_vec(),
            distributed_rule: config.distributed_rule,
            budget: config.budget,
            omp: config.omp,
            identities: header.identities.is_some(),
            initial_identity: header.initial_identity.clone(),
            factored_identity: config.factored_identity.filter(|_| {
                header.identities.is_some()
                    && header.initial_identity.is_some()
                    && config.factored.is_some()
            }),
        };
        begin.check().map_err(RouterError::Begin)?;
        let interests = idmesh_placement::interests(&begin)?;
        let mut router = Router {
            regions,
            positions: vec![None; tracks],
            begin: begin.clone(),
            header: header.clone(),
            interests,
            followed_at: vec![vec![0; tracks]; leaders],
            mixing_log: MixingLog::new(tracks),
            seq: 0,
            events: 0,
            log: Vec::new(),
            touching: begin
                .factored
                .as_ref()
                .is_some_and(|f| f.shrink)
                .then(|| vec![VecDeque::new(); tracks]),
            outbox: vec![Vec::new(); leaders],
            config,
        };
        let seq = router.next_seq();
        for outbox in &mut router.outbox {
            outbox.push(Sequenced {
                seq,
                item: Item::Begin(begin.clone()),
            });
        }
        Ok(router)
    }

    pub(crate) fn begin(&self) -> &Begin {
        &self.begin
    }

    /// The header the stream started from.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The seq of the last item.
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// Trace events routed so far.
    pub fn events(&self) -> u64 {
        self.events
    }

    pub(crate) fn leaders(&self) -> usize {
        self.outbox.len()
    }

    fn next_seq(&mut self) -> u64 {
        self.seq += 1;
        self.seq
    }

    /// Routes one trace line (header and truth lines carry no event and are
    /// skipped), with the handovers it makes before and after ([`Regions::before`],
    /// [`Regions::after`]). An
    /// identity read goes to the track's owner alone.
    pub(crate) fn line(&mut self, line: &Line) {
        let (rides, before): (Vec<_>, Vec<_>) =
            self.regions.before(line).into_iter().partition(|h| h.rides);
        self.route_handovers(before);
        // A handover that rides on its mix goes in the mix's item; an
        // adoption, in the adopted track's first item.
        let (adopted, rides): (Vec<_>, Vec<_>) = rides.into_iter().partition(|h| h.from == UNHELD);
        let handed = rides.first().map(|h| Handed {
            track: h.track,
            from: h.from,
        });
        let adopted: Vec<u32> = adopted.iter().map(|h| h.track).collect();
        self.route_line(line, handed, adopted);
        let after = self.regions.after(line);
        self.route_handovers(after);
    }

    fn route_handovers(&mut self, handovers: Vec<Handover>) {
        for handover in handovers {
            self.route(Item::Handover {
                track: handover.track,
                from: handover.from,
                to: handover.to,
            });
        }
    }

    fn route_line(&mut self, line: &Line, handed: Option<Handed>, adopted: Vec<u32>) {
        let adopts = |track: u32| adopted.contains(&track);
        match line {
            Line::Mix(mix) => {
                self.events += 1;
                self.mixing_log.record(mix.a, mix.b);
                let item = Item::Mix {
                    a: mix.a,
                    b: mix.b,
                    swap: mix.swap,
                    owner_a: self.owner(mix.a),
                    owner_b: self.owner(mix.b),
                    handed,
                    adopted,
                };
                self.route(item);
            }
            Line::Observe(observe) => {
                self.events += 1;
                let likelihood = idmesh_belief::Observe {
                    track: observe.track,
                    red: observe.red,
                    blue: observe.blue,
                };
                // The stream's belief, as its Begin says.
                let (growth, global) = if self.begin.factored.is_some() {
                    // An observation changes the observed track's
                    // component alone, held by one leader that follows it.
                    (Growth::Meeting(Vec::new()), false)
                } else if self.config.distributed_rule {
                    (
                        Growth::Meeting(self.mixing_log.partners(observe.track).to_vec()),
                        RadonShare::observation_is_global(&likelihood, false),
                    )
                } else {
                    (Growth::All, true)
                };
                self.mixing_log.clear(observe.track);
                self.route(Item::Observe {
                    track: observe.track,
                    red: observe.red,
                    blue: observe.blue,
                    growth,
                    global,
                    adopted_by: adopts(observe.track).then(|| self.owner(observe.track)),
                });
            }
            Line::Move(m) => {
                self.events += 1;
                self.positions[m.track as usize] = Some([m.x, m.y]);
            }
            Line::Identify(read) => {
                self.events += 1;
                // Only the owner holds the track's row; nobody else hears.
                let owner = self.owner(read.track);
                self.route(Item::Identify {
                    track: read.track,
                    identity: read.identity,
                    accuracy: read.accuracy,
                    owner,
                    adopted: adopts(read.track),
                });
            }
            // Refused on the way in (`Problem::NotExtracted`): a detect
            // line reaches no router.
            Line::Header(_) | Line::Truth(_) | Line::Detect(_) => {}
        }
    }

    /// The leader surveilling `track` (lines were checked against the
    /// header, so the track exists).
    fn owner(&self, track: u32) -> u16 {
        self.regions.owner(track).unwrap_or(0)
    }

    fn route(&mut self, item: Item) {
        let seq = self.next_seq();
        match item {
            Item::Handover { track, to, .. }
            | Item::Mix {
                handed: Some(Handed { track, .. }),
                owner_a: to,
                ..
            } => self.followed_at[to as usize][track as usize] = seq,
            _ => {}
        }
        for (track, to) in item.adoptions() {
            self.followed_at[to as usize][track as usize] = seq;
        }
        for (interest, outbox) in self.interests.iter_mut().zip(&mut self.outbox) {
            if interest.receives(&item) {
                interest.note(&item);
                outbox.push(Sequenced {
                    seq,
                    item: item.clone(),
                });
            }
        }
        if let Some(touching) = &mut self.touching {
            match item {
                Item::Mix { a, b, .. } => {
                    touching[a as usize].push_back(seq);
                    touching[b as usize].push_back(seq);
                }
                Item::Observe { track, .. } => touching[track as usize].push_back(seq),
                // A read changes the tree of its track, wherever it lies.
                Item::Identify { track, .. } if self.begin.factored_identity.is_some() => {
                    touching[track as usize].push_back(seq)
                }
                _ => {}
            }
        }
        self.log.push(Sequenced { seq, item });
    }

    /// Where every track was last seen and who surveils it, after the
    /// events routed so far.
    pub fn positions(&self, sensor: &str, finished: bool) -> SensorPositions {
        let mut places: Vec<_> = (self.regions.places().into_iter())
            .map(|p| p.map(|(x, y)| [x, y]))
            .collect();
        // One per leader: a crowd held whole places none of them.
        places.resize(self.begin.leaders.len(), None);
        SensorPositions {
            sensor: sensor.to_string(),
            events: self.events,
            finished,
            leaders: self.begin.leaders.clone(),
            places,
            regions: self.regions.cells(),
            positions: self.positions.clone(),
            owners: self.regions.owners().to_vec(),
        }
    }

    /// Places the cut `wanted` in every leader's stream: (seq of the cut,
    /// events in it).
    pub(crate) fn cut(&mut self, wanted: Wanted) -> (u64, u64) {
        let seq = self.next_seq();
        let item = Item::Cut {
            events: self.events,
            tag: wanted.tag,
            rows: wanted.rows,
        };
        for outbox in &mut self.outbox {
            outbox.push(Sequenced {
                seq,
                item: item.clone(),
            });
        }
        (seq, self.events)
    }

    /// A leader follows more tracks from `after` on: the items it was not
    /// sent that touch them (as the interest rule grows them).
    pub fn follow(&mut self, follow: &Follow) -> Result<Vec<Sequenced>, RouterError> {
        let leader = follow.leader as usize;
        let tracks = self.begin.tracks;
        if leader >= self.interests.len() {
            return Err(RouterError::UnknownLeader(follow.leader));
        }
        if let Some(&track) = follow.tracks.iter().find(|&&t| t >= tracks) {
            return Err(RouterError::UnknownTrack { track, tracks });
        }
        for &t in &follow.tracks {
            let at = &mut self.followed_at[leader][t as usize];
            *at = (*at).max(follow.after);
        }
        if let Some(touching) = &self.touching {
            // A factored stream: the items on the tracks, nothing grown.
            let mut seqs: Vec<u64> = follow
                .tracks
                .iter()
                .flat_map(|&t| {
                    let on = &touching[t as usize];
                    on.range(on.partition_point(|&s| s <= follow.after)..)
                })
                .copied()
                .collect();
            seqs.sort_unstable();
            seqs.dedup();
            let missed = seqs
                .iter()
                .filter_map(|&seq| {
                    let at = self.log.binary_search_by_key(&seq, |s| s.seq).ok()?;
                    Some(self.log[at].clone())
                })
                .collect();
            let interest = &mut self.interests[leader];
            for &t in &follow.tracks {
                interest.add(t);
            }
            return Ok(missed);
        }
        let mut grown = Interest::new(follow.leader, tracks as usize, false);
        if self.begin.factored_identity.is_some() {
            grown = grown.reading_trees();
        }
        for &t in &follow.tracks {
            grown.add(t);
        }
        // Grown this far, the leader may hold a set that fixes every track
        // (see `Interest::saturated`): then it needs every observation it
        // was not sent while it followed fewer. Sending some again is
        // harmless (the leader waits at `after`; duplicates collapse by
        // seq).
        let mut whole = self.interests[leader].clone();
        for &t in &follow.tracks {
            whole.add(t);
        }
        let saturated = whole.saturated();
        // Items are logged in seq order, one per seq except Begin and cuts.
        let from = self.log.partition_point(|s| s.seq <= follow.after);
        let mut missed = Vec::new();
        for sequenced in &self.log[from..] {
            let observation = matches!(sequenced.item, Item::Observe { .. });
            if (saturated && observation)
                || matches!(
                    sequenced.item,
                    Item::Mix { .. } | Item::Observe { .. } | Item::Identify { .. }
                ) && grown.receives(&sequenced.item)
            {
                grown.note(&sequenced.item);
                missed.push(sequenced.clone());
            }
        }
        let interest = &mut self.interests[leader];
        for t in grown.tracks() {
            interest.add(t);
        }
        Ok(missed)
    }

    /// A leader of a factored stream no longer needs some tracks' events
    /// since item `after`: each is dropped from its interest unless it
    /// entered it again at or after `after` (the request is then stale;
    /// requests are fire and forget, so they may come late or twice).
    /// Returns how many tracks were dropped.
    pub fn unfollow(&mut self, unfollow: &Unfollow) -> Result<usize, RouterError> {
        let leader = unfollow.leader as usize;
        let tracks = self.begin.tracks;
        let Some(interest) = self.interests.get_mut(leader) else {
            return Err(RouterError::UnknownLeader(unfollow.leader));
        };
        if let Some(&track) = unfollow.tracks.iter().find(|&&t| t >= tracks) {
            return Err(RouterError::UnknownTrack { track, tracks });
        }
        if interest.grows() {
            return Err(RouterError::Unfollow);
        }
        let since = &self.followed_at[leader];
        Ok(unfollow
            .tracks
            .iter()
            .filter(|&&t| since[t as usize] < unfollow.after && interest.remove(t))
            .count())
    }

    /// Every leader has its state safe through item `seq`: no follow
    /// request will ask for items at or before it again, so the log drops
    /// them. Returns how many it dropped.
    pub(crate) fn forget(&mut self, seq: u64) -> usize {
        let through = self.log.partition_point(|s| s.seq <= seq);
        self.log.drain(..through);
        for on in self.touching.iter_mut().flatten() {
            let passed = on.partition_point(|&s| s <= seq);
            on.drain(..passed);
        }
        through
    }

    /// Items kept for follow requests.
    pub(crate) fn logged(&self) -> usize {
        self.log.len()
    }

    /// The items queued for leader `i` since the last call.
    /// Whether items wait in leader `i`'s queue.
    pub(crate) fn queued(&self, i: usize) -> bool {
        self.outbox.get(i).is_some_and(|o| !o.is_empty())
    }

    pub fn take(&mut self, i: usize) -> Vec<Sequenced> {
        std::mem::take(&mut self.outbox[i])
    }
}
