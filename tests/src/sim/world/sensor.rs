//! The sensor's part of a schedule, as `sensor/src/driver.rs` runs it:
//! reading the lines (from a trace, or a producer on the ingest key) into
//! the [`Gateway`], sending its batches, answering the leaders' follow and
//! resend gets and the coordinator's cuts, and the sensor killed and
//! started again from its journal.

use super::coordinator::ToCoordinator;
use super::leader::{ToLeader, Who};
use super::sensor_standby::standing;
use super::{Event, Msg, World, STALL_CHECK};
use crate::sim::network::Endpoint;
use crate::sim::Violation;
use idmesh_protocol::wire::encode;
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_sensor::Offer;
use idmesh_sensor::Router;
use idmesh_sensor::{CutOutcome, Gateway};
use idmesh_sensor::{CutParameters, Placed};
use rand::Rng;

#[derive(Debug, Clone)]
pub(crate) enum ToSensor {
    Follow {
        ask: u64,
        bytes: Vec<u8>,
    },
    Resend {
        ask: u64,
        bytes: Vec<u8>,
    },
    Durable(Vec<u8>),
    /// How far a leader has got (flow control).
    Progress(Vec<u8>),
    /// A leader stops following tracks (fire and forget).
    Unfollow(Vec<u8>),
    /// The coordinator asks for a cut (from = usize::MAX).
    Cut {
        id: u64,
        parameters: CutParameters,
    },
}

impl World {
    /// Reads the next few lines, as the gateway's actor does by chunks.
    pub(super) fn sensor_step(&mut self) -> Result<(), Violation> {
        // Gone with its host: its standby's adoption starts the steps again.
        if self.sensor_down() {
            return Ok(());
        }
        let lines = self.scenario.lines.len();
        let mut chunk = self.rng.gen_range(1..=4usize);
        // Flow control: held, the sensor looks again later, as the actor
        // does when no progress mark wakes it.
        if let Some(room) = self.gateway.room() {
            if room == 0 && self.next_line < lines {
                self.tally.window_waits += 1;
                // As the actor's stall check: batches a leader still
                // waits for, again, at an interval longer than a sweep.
                if self.now >= self.stall_checked + STALL_CHECK {
                    self.stall_checked = self.now;
                    for (i, batch) in self.gateway.stalled() {
                        self.send_batch(i, &batch);
                    }
                }
                let wait = self.rng.gen_range(1..=40);
                self.net.at(self.now + wait, Event::SensorStep);
                return Ok(());
            }
            chunk = chunk.min(room as usize);
        }
        let mut placed = Vec::new();
        let end = (self.next_line + chunk).min(lines);
        if self.producer.is_some() {
            placed = self.ingest(self.next_line, end)?;
        } else {
            for line in &self.scenario.lines[self.next_line..end] {
                placed.extend(self.gateway.line(line));
            }
        }
        self.next_line = end;
        let refused = if self.next_line >= lines && !self.gateway.finished() {
            self.gateway.end()
        } else {
            Vec::new()
        };
        self.flush()?;
        for p in placed {
            self.reply_cut(p.query, Ok(encode(&p.answer)));
        }
        for (id, why) in refused {
            self.reply_cut(id, Err(why));
        }
        if self.next_line < lines {
            let wait = self.rng.gen_range(1..=40);
            self.net.at(self.now + wait, Event::SensorStep);
        }
        Ok(())
    }

    /// Lines `from..to` sent by the producer (its counters are the line
    /// numbers), as a producer whose replies are lost now and then does:
    /// each mistake must be refused or deduplicated and route nothing;
    /// the request itself must be taken whole.
    pub(super) fn ingest(&mut self, from: usize, to: usize) -> Result<Vec<Placed<u64>>, Violation> {
        let Some(mut producer) = self.producer.take() else {
            return Ok(Vec::new());
        };
        let text = |lines: &[idmesh_protocol::trace::Line]| {
            lines
                .iter()
                .map(|l| serde_json::to_string(l).unwrap_or_default())
                .collect::<Vec<_>>()
                .join("\n")
        };
        let lines = &self.scenario.lines;
        let events = self.gateway.router().events();
        let mut placed = Vec::new();
        let offer = |gateway: &mut Gateway<u64>, who: &str, counter: usize, payload: &str| {
            let counter = counter.to_string();
            gateway
                .ingest(Offer {
                    producer: Some(who),
                    counter: Some(&counter),
                    payload: payload.as_bytes(),
                    time: None,
                    finish: false,
                })
                .map_err(|e| Violation::new(format!("ingest from {who} refused: {e}")))
        };
        if producer.gen_bool(0.2) {
            let ahead = from + producer.gen_range(1..=3);
            let (ack, reached) = offer(&mut self.gateway, "sim", ahead, &text(&lines[from..to]))?;
            if !ack.accepted.is_empty() || !reached.is_empty() || ack.next != from as u64 {
                return Err(Violation::new(format!(
                    "counter {ahead} ahead of {from} was taken: {ack:?}"
                )));
            }
        }
        if producer.gen_bool(0.1) {
            let (ack, _) = offer(
                &mut self.gateway,
                &format!("junk-{from}"),
                0,
                "{\"kind\":\"mix\"",
            )?;
            if !ack.accepted.is_empty() || ack.errors.len() != 1 {
                return Err(Violation::new(format!(
                    "a malformed line was taken: {ack:?}"
                )));
            }
        }
        let (ack, reached) = offer(&mut self.gateway, "sim", from, &text(&lines[from..to]))?;
        let wanted: Vec<u64> = (from as u64..to as u64).collect();
        if ack.accepted != wanted || ack.events != events + wanted.len() as u64 {
            return Err(Violation::new(format!(
                "lines {from}..{to} not taken whole: {ack:?}"
            )));
        }
        placed.extend(reached);
        if producer.gen_bool(0.3) {
            // The reply was lost: the producer sends again, with history.
            let back = producer.gen_range(0..=from);
            let (ack, reached) = offer(&mut self.gateway, "sim", back, &text(&lines[back..to]))?;
            if !ack.accepted.is_empty() || !reached.is_empty() || ack.duplicates.len() != to - back
            {
                return Err(Violation::new(format!(
                    "lines {back}..{to} sent again were taken again: {ack:?}"
                )));
            }
        }
        self.producer = Some(producer);
        Ok(placed)
    }

    /// The leaders' next batches, on their way once the journal (and the
    /// standby, if one is up) holds what they depend on
    /// (`Wire::flush` in sensor/src/driver.rs).
    pub(super) fn flush(&mut self) -> Result<(), Violation> {
        let mut batches = self.gateway.flush();
        self.sync()?;
        // The role may have moved to a new epoch meanwhile.
        self.gateway.restamp(&mut batches);
        for (i, batch) in batches {
            self.note_routed(i, &batch);
            self.send_batch(i, &batch);
        }
        Ok(())
    }

    /// The sensor puts `batch` on leader `i`'s event key.
    pub(super) fn send_batch(&mut self, i: usize, batch: &Batch) {
        self.send(
            Endpoint::Sensor,
            Endpoint::Leader(i),
            Msg::Leader {
                to: i,
                what: ToLeader::Batch(encode(batch)),
            },
        );
    }

    pub(super) fn note_routed(&mut self, i: usize, batch: &Batch) {
        self.routed[i].extend(batch.items.iter().map(|s| s.seq));
    }

    pub(super) fn reply_cut(&mut self, id: u64, reply: Result<Vec<u8>, String>) {
        self.send(
            Endpoint::Sensor,
            Endpoint::Coordinator,
            Msg::Coordinator(ToCoordinator::Cut { id, reply }),
        );
    }

    /// A message of `from` (holding its role at `epoch`) reaches the
    /// sensor: if the sensor has been handed a newer epoch of that role
    /// since it started, it must refuse it (its refusals grow), and it is
    /// counted as fenced.
    pub(super) fn at_sensor_fenced(
        &mut self,
        from: Who,
        epoch: u64,
        what: ToSensor,
    ) -> Result<(), Violation> {
        let aimed =
            matches!(what, ToSensor::Resend { .. }) && self.now < self.aimed.refuse_resends_until;
        if matches!(what, ToSensor::Cut { .. }) || aimed {
            return self.at_sensor(from, what, false);
        }
        let heard = self.sensor_heard.get(&from.role).copied();
        let Some(newest) = heard.filter(|&h| epoch < h) else {
            let heard = self.sensor_heard.entry(from.role).or_insert(epoch);
            *heard = (*heard).max(epoch);
            return self.at_sensor(from, what, false);
        };
        let before = self.gateway.stats().rejected;
        self.at_sensor(from, what, true)?;
        if self.gateway.stats().rejected <= before {
            return Err(Violation::new(format!(
                "the sensor applied a message of {} at epoch {epoch}, older than the epoch {newest} it had heard",
                self.leaders[from.role].name
            )));
        }
        self.tally.fenced += 1;
        Ok(())
    }

    /// `stale`: from a former holder the sensor must refuse.
    pub(super) fn at_sensor(
        &mut self,
        from: Who,
        what: ToSensor,
        stale: bool,
    ) -> Result<(), Violation> {
        match what {
            ToSensor::Follow { ask, bytes } => {
                let answer = self.gateway.follow(&bytes);
                // Its items count as routed once the leader takes the
                // reply ([`World::answer_ask`]): one lost on the way, or a
                // duplicate request's, never reaches it.
                if answer.is_ok() {
                    self.flush()?;
                }
                self.reply_leader(from, ask, answer.map(|f| encode(&f)));
            }
            ToSensor::Resend { ask, bytes } => {
                let answer = if self.now < self.aimed.refuse_resends_until {
                    Err("resend refused (the simulator's aimed fault)".to_string())
                } else {
                    self.gateway.resend(&bytes).map(|r| encode(&r))
                };
                self.sync()?;
                self.reply_leader(from, ask, answer);
            }
            ToSensor::Durable(bytes) => self.gateway.durable(&bytes, "sim"),
            ToSensor::Progress(bytes) => self.gateway.progress(&bytes, "sim"),
            // A leader's own request is well formed: a refusal is a bug.
            ToSensor::Unfollow(bytes) => match self.gateway.unfollow(&bytes) {
                Err(e) if !stale => {
                    return Err(Violation::new(format!(
                        "the sensor refused leader {}'s unfollow: {e}",
                        from.role
                    )))
                }
                _ => {}
            },
            ToSensor::Cut { id, parameters } => match self.gateway.cut(id, &parameters) {
                CutOutcome::Placed(p) => {
                    self.flush()?;
                    self.reply_cut(id, Ok(encode(&p.answer)));
                }
                CutOutcome::Scheduled => {}
                CutOutcome::Refused(id, why) => {
                    self.sync()?;
                    self.reply_cut(id, Err(why))
                }
            },
        }
        // What the message changed (a durable mark, progress, interests)
        // on disk before the next thing leaves.
        self.sync()
    }

    pub(super) fn reply_leader(&mut self, to: Who, ask: u64, reply: Result<Vec<u8>, String>) {
        let what = ToLeader::Reply { ask, reply };
        let msg = match to.former {
            false => Msg::Leader { to: to.role, what },
            true => Msg::Former { to: to.role, what },
        };
        self.send(Endpoint::Sensor, to.endpoint(), msg);
    }

    /// The sensor killed and started again: a new gateway restored from the
    /// journal must be where the old one was — the same seq, events and
    /// trace position (the producer's counter is checked by its next
    /// request, which must be taken whole). Cuts it held for a later point
    /// die with it: their queries time out. Half the time the journal is
    /// compacted first, as the process does once it has grown.
    pub(super) fn sensor_crash(&mut self) -> Result<(), Violation> {
        self.tally.sensor_crashes += 1;
        self.journal.extend(self.gateway.unjournaled());
        if self.rng.gen_bool(0.5) {
            self.tally.sensor_compactions += 1;
            self.journal = self
                .gateway
                .compacted()
                .map_err(|e| Violation::new(format!("the sensor cannot snapshot: {e}")))?;
        }
        let router = Router::new(self.scenario.router(), &self.scenario.header)
            .map_err(|e| Violation::setup(e.to_string()))?;
        let mut restored = self.scenario.gateway(router);
        restored
            .restore(self.journal.clone(), &self.scenario.lines)
            .map_err(|e| Violation::new(format!("the sensor cannot restore: {e}")))?;
        // It holds its role at the epoch it held it at.
        restored.advance_epoch(self.gateway.epoch());
        if standing(&restored) != standing(&self.gateway) {
            return Err(Violation::new(format!(
                "the sensor restored from its journal at (seq, events, finished, trace lines) {:?}, not {:?}",
                standing(&restored),
                standing(&self.gateway)
            )));
        }
        self.gateway = restored;
        // A sensor restarted knows no epoch: it fences from the next.
        self.sensor_heard.clear();
        self.sensor_restarted();
        Ok(())
    }
}
