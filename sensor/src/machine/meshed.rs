//! The gateway as one sensor of several ([`crate::mesh`]): its
//! producers' events go into its intake, every sensor's intake is merged,
//! and the merged order is routed as one sensor's stream would be. What
//! the merge releases may answer cuts asked of this sensor; those answers
//! and refusals wait in the gateway for the driver
//! ([`Gateway::answered`], [`Gateway::refused`]).

use super::*;
use crate::journal::MeshRecord;
use crate::mesh::{Mesh, MeshConfig};
use idmesh_protocol::wire::sensor_to_sensor::{Entry, IntakeSlice, IntakeWanted, Position};

impl<Q> Gateway<Q> {
    /// Makes this gateway one of several sensors: events only through
    /// its intake, the stream routed in the merged order, batches sent
    /// only to the leaders it serves. The stream finishes once every
    /// sensor has finished and everything is merged.
    pub(crate) fn meshed(mut self, config: &MeshConfig) -> Self {
        self.state.mesh = Some(Mesh::new(config));
        self.state.ingest.gapped();
        self.state.finished = false;
        self
    }

    /// One sensor of several.
    pub(crate) fn mesh(&self) -> Option<&Mesh> {
        self.state.mesh.as_ref()
    }

    /// Cut answers the merge made ready: send them after the next flush.
    pub(crate) fn answered(&mut self) -> Vec<Placed<Q>> {
        std::mem::take(&mut self.answers)
    }

    /// Cut requests refused since the last call, with why.
    pub(crate) fn refused(&mut self) -> Vec<(Q, String)> {
        std::mem::take(&mut self.refusals)
    }

    /// An ingest request to one sensor of several: the lines go into its
    /// intake (each after the last position it took, or refused as late),
    /// then its tick and finish.
    pub(super) fn ingest_meshed(&mut self, offer: Offer<'_>) -> Result<IngestAck, IngestRefusal> {
        let time = match offer.time {
            None => None,
            Some(t) => match t.parse::<f64>() {
                Ok(t) if t.is_finite() => Some(t),
                _ => {
                    self.state.stats.rejected += 1;
                    return Err(IngestRefusal::BadTime(t.to_string()));
                }
            },
        };
        let mesh = self.state.mesh.as_mut().ok_or(IngestRefusal::Finished)?;
        if mesh.intake.finished() && (!offer.payload.is_empty() || time.is_some()) {
            self.state.stats.rejected += 1;
            return Err(IngestRefusal::Finished);
        }
        let control_only = offer.payload.is_empty() && (time.is_some() || offer.finish);
        let mut ack = if control_only {
            IngestAck {
                sensor: self.name.clone(),
                producer: offer.producer.unwrap_or_default().to_string(),
                ..IngestAck::default()
            }
        } else {
            let judged = self.state.ingest.offer_admitted(
                offer,
                &mut self.state.stats,
                &mut |line, text, producer, counter| {
                    let position =
                        Position::event(line.time().unwrap_or_default(), producer, counter);
                    if let Some(late) = mesh.intake.refuses(&position) {
                        return Err(late);
                    }
                    mesh.take(position, text.to_string());
                    Ok(())
                },
            )?;
            judged.ack
        };
        if let Some(time) = time {
            mesh.tick(time);
        }
        if offer.finish {
            mesh.finish();
        }
        ack.events = mesh.taken_events();
        self.note(Record::Mesh(MeshRecord::Offer {
            producer: offer.producer.map(str::to_owned),
            counter: offer.counter.map(str::to_owned),
            payload: offer.payload.to_vec(),
            time: offer.time.map(str::to_owned),
            finish: offer.finish,
        }));
        self.drain();
        Ok(ack)
    }

    /// A peer's slice of its intake (`IntakeSlice` bytes): merged.
    pub(crate) fn peer(&mut self, bytes: &[u8]) -> Result<(), String> {
        let answer = decode::<IntakeSlice>(bytes)
            .map_err(|e| e.to_string())
            .and_then(|slice| {
                self.state
                    .mesh
                    .as_mut()
                    .ok_or_else(|| "this sensor is the only one".to_string())?
                    .peer(slice)
            });
        self.count("intake slice", &answer);
        if answer? {
            self.note(Record::Mesh(MeshRecord::Peer(bytes.to_vec())));
            self.drain();
        }
        Ok(())
    }

    /// A peer asks for this sensor's intake (`IntakeWanted` bytes): the
    /// slice and whether it tells the peer anything new (an entry, a
    /// watermark or an end it did not know: else the driver may hold the
    /// request, see `IntakeWanted::known`), or why not (counted).
    pub(crate) fn intake(&mut self, bytes: &[u8]) -> Result<(IntakeSlice, bool), String> {
        let answer = decode::<IntakeWanted>(bytes)
            .map_err(|e| e.to_string())
            .and_then(|wanted| {
                let mesh = self
                    .state
                    .mesh
                    .as_mut()
                    .ok_or_else(|| "this sensor is the only one".to_string())?;
                let (slice, changed) = mesh.slice(&wanted.sensor, wanted.from, &wanted.above)?;
                let news = !slice.entries.is_empty()
                    || slice.watermark != wanted.known
                    || slice.finished != wanted.known_finished;
                Ok(((slice, news), changed.then_some(wanted)))
            });
        self.count("intake request", &answer);
        let (slice, changed) = answer?;
        if let Some(wanted) = changed {
            self.note(Record::Mesh(MeshRecord::Asked {
                peer: wanted.sensor,
                from: wanted.from,
                above: wanted.above,
            }));
            self.drain();
        }
        Ok(slice)
    }

    /// What to ask each peer for next: its name and the request's bytes.
    pub(crate) fn wanted(&self) -> Vec<(String, Vec<u8>)> {
        let Some(mesh) = &self.state.mesh else {
            return Vec::new();
        };
        mesh.peers()
            .into_iter()
            .map(|(peer, from, known, known_finished)| {
                let wanted = IntakeWanted {
                    version: VERSION,
                    sensor: mesh.name().to_string(),
                    from,
                    above: mesh.intake.watermark().clone(),
                    known,
                    known_finished,
                };
                (peer, encode(&wanted))
            })
            .collect()
    }

    /// A cut asked of one sensor of several: answered from memory if its
    /// tag was merged already, else taken into the intake (unless a peer's
    /// entry with its tag is on its way) and answered once merged.
    pub(super) fn cut_meshed(&mut self, query: Q, parameters: &CutParameters) -> CutOutcome<Q> {
        let (wanted, events) = match parameters.parse() {
            Ok(parsed) => parsed,
            Err(reason) => {
                self.count::<()>("cut", &Err(reason.clone()));
                return CutOutcome::Refused(query, reason);
            }
        };
        let tag = wanted.tag;
        let Some(mesh) = self.state.mesh.as_mut() else {
            return CutOutcome::Refused(query, "this sensor is the only one".into());
        };
        match mesh.recalled(tag) {
            Some(Ok(answer)) => {
                return CutOutcome::Placed(Placed {
                    query,
                    wanted,
                    answer: answer.clone(),
                })
            }
            Some(Err(reason)) => return CutOutcome::Refused(query, reason.clone()),
            None => {}
        }
        let asked = mesh.merged_cut(tag) || self.waiting.contains_key(&tag);
        self.waiting.entry(tag).or_default().push(query);
        if !asked {
            mesh.cut(tag, wanted.rows, events);
            self.note(Record::Mesh(MeshRecord::Cut {
                tag,
                rows: wanted.rows,
                events,
            }));
            self.drain();
        }
        CutOutcome::Scheduled
    }

    /// Every cut query waiting for the merge is refused with `reason` (a
    /// peer it waits for does not answer). The cuts stay in the order: a
    /// query asked again once the peer is back is answered.
    pub(crate) fn refuse_waiting(&mut self, reason: &str) {
        for (_, queries) in std::mem::take(&mut self.waiting) {
            self.refusals
                .extend(queries.into_iter().map(|q| (q, reason.to_string())));
        }
    }

    /// The sensors the merge waits for (to name them when it cannot go
    /// on: a cut then cannot be placed).
    pub(crate) fn waiting_for(&self) -> Vec<String> {
        self.state
            .mesh
            .as_ref()
            .map_or_else(Vec::new, |m| m.merge.waiting_for())
    }

    /// Takes again what a journaled [`MeshRecord`] did.
    pub(super) fn replay_mesh(&mut self, record: MeshRecord) -> Result<(), String> {
        match record {
            MeshRecord::Offer {
                producer,
                counter,
                payload,
                time,
                finish,
            } => {
                let offer = Offer {
                    producer: producer.as_deref(),
                    counter: counter.as_deref(),
                    payload: &payload,
                    time: time.as_deref(),
                    finish,
                };
                self.ingest_meshed(offer)
                    .map_err(|e| format!("an ingest request it accepted is refused now: {e}"))?;
            }
            MeshRecord::Peer(bytes) => self.peer(&bytes)?,
            MeshRecord::Cut { tag, rows, events } => {
                if let Some(mesh) = self.state.mesh.as_mut() {
                    mesh.cut(tag, rows, events);
                }
                self.drain();
            }
            MeshRecord::Asked { peer, from, above } => {
                if let Some(mesh) = self.state.mesh.as_mut() {
                    mesh.slice(&peer, from, &above)?;
                }
                self.drain();
            }
        }
        Ok(())
    }

    /// Routes what the merge lets go, in its order: events through the
    /// router, cuts placed (or scheduled, or refused) at their point; and,
    /// once every sensor finished and all is merged, the stream's end.
    pub(super) fn drain(&mut self) {
        let name = self.name.clone();
        let epoch = self.epoch;
        loop {
            let Some(mesh) = self.state.mesh.as_mut() else {
                return;
            };
            let Some((origin, entry)) = mesh.merge.release() else {
                break;
            };
            match entry {
                Entry::Line(text) => {
                    // Checked where it was taken; a peer's bytes are
                    // checked again, and every sensor skips the same.
                    match self.state.ingest.event(&text) {
                        Ok(line) => {
                            // Acknowledged before the merge: a refusal
                            // here is counted and logged, not answered.
                            let _ = self.route_line(&line);
                            let Some(mesh) = self.state.mesh.as_mut() else {
                                return;
                            };
                            let mut placed = Vec::new();
                            mesh.cuts
                                .reached(&mut self.state.router, (&name, epoch), &mut placed);
                            for p in placed {
                                self.answer_tag(p);
                            }
                        }
                        Err(reason) => {
                            self.state.stats.rejected += 1;
                            tracing::warn!(sensor = %mesh.merge.sensors()[origin], %reason,
                                "a merged line is no event of this stream: skipped");
                        }
                    }
                }
                Entry::Cut { tag, rows, events } => {
                    if mesh.merged_cut(tag) {
                        continue;
                    }
                    let finished = self.state.finished;
                    let wanted = Wanted { tag, rows };
                    match mesh
                        .cuts
                        .sort(tag, wanted, events, &self.state.router, finished)
                    {
                        Request::Now { wanted, query } => {
                            let placed = place(
                                &mut self.state.router,
                                (&name, epoch),
                                wanted,
                                query,
                                finished,
                            );
                            self.answer_tag(placed);
                        }
                        Request::Scheduled => {}
                        Request::Refused { query, reason }
                        | Request::Malformed { query, reason } => self.refuse_tag(query, reason),
                    }
                }
            }
        }
        let Some(mesh) = self.state.mesh.as_mut() else {
            return;
        };
        self.state.stats.merged = mesh.merge.merged().iter().sum();
        self.state.stats.merged_twice = mesh.merge.twice();
        if mesh.merge.complete() && !mesh.ended {
            mesh.ended = true;
            self.finish_extraction();
            self.state.finished = true;
            self.state.owed.fill(true);
            let Some(mesh) = self.state.mesh.as_mut() else {
                return;
            };
            for (tag, reason) in mesh.cuts.refuse_all(&self.state.router) {
                self.refuse_tag(tag, reason);
            }
        }
    }

    /// The cut tagged `placed.query` is placed: every query for it here
    /// gets the answer, with each sensor's events in it.
    fn answer_tag(&mut self, mut placed: Placed<u64>) {
        let tag = placed.query;
        if let Some(mesh) = self.state.mesh.as_mut() {
            placed.answer.origins = mesh.origins();
            mesh.remember(tag, Ok(placed.answer.clone()));
        }
        for query in self.waiting.remove(&tag).unwrap_or_default() {
            self.answers.push(Placed {
                query,
                wanted: placed.wanted,
                answer: placed.answer.clone(),
            });
        }
    }

    /// The cut tagged `tag` cannot be placed: every query for it is told.
    fn refuse_tag(&mut self, tag: u64, reason: String) {
        if let Some(mesh) = self.state.mesh.as_mut() {
            mesh.remember(tag, Err(reason.clone()));
        }
        for query in self.waiting.remove(&tag).unwrap_or_default() {
            self.refusals.push((query, reason.clone()));
        }
    }
}
