//! The sensor's journal replicated to its standby, as a pure state
//! machine: what goes to the standby, what its answers mean, and when what
//! depends on the records just appended may leave the sensor. The driver
//! (`crate::standby`) only moves the bytes and watches the standby's
//! liveliness token.
//!
//! Two halves: [`Replication`], the sensor's side, and [`Copy`], the
//! standby's (what a [`Replicate`] does to its copy of the journal).
//!
//! The rule that makes "nothing acknowledged is lost" hold when the
//! sensor's host dies: while the standby is up, records are released
//! ([`Step::Release`]) only once it has said it holds them on its disk.
//! While it is down the sensor goes on alone (waiting for a process that
//! is gone would stop the stream); when it comes back it is sent the
//! whole journal, compacted, before any append, and after a compaction
//! too (the sensor's journal then starts again from the compacted form).
//!
//! With voters, going on alone is safe only once the standby's copy can no
//! longer take the role over: every message carries the sensor's epoch,
//! the copy notes the newest epoch it holds every record of
//! ([`Copy::epoch`]), and a takeover names that epoch; the sensor moves
//! its role to a new epoch before it releases what the standby did not
//! acknowledge (the driver's business: `crate::standby`), so a copy left
//! behind while both still reached the voters loses its claim.

use idmesh_protocol::wire::sensor_to_standby::{Position, Replicate};
use idmesh_protocol::wire::VERSION;

/// What the driver does next with the records it appended.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// They may leave: the standby holds them, or there is none up.
    Release,
    /// Send this to the standby and wait for its answer.
    Send(Replicate),
    /// Send the whole journal (its compacted form, which the driver makes:
    /// [`Replication::whole`]) before anything else.
    NeedWhole,
}

/// The standby's liveliness changed, for the driver to log (once per
/// change, not once per batch).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Presence {
    /// It went away: the sensor goes on alone.
    Gone,
    /// It is back (or up for the first time): it gets the whole journal.
    Back,
}

/// The sensor's side of the replication.
#[derive(Debug, Clone)]
pub struct Replication {
    sensor: String,
    incarnation: u64,
    /// The epoch the sensor holds its role at (0 without voters).
    epoch: u64,
    /// The standby's token is present.
    present: bool,
    /// The current reset, and the records sent in it.
    reset: u64,
    sent: u64,
    /// The standby's copy must be replaced before any append: it has
    /// none of this run yet, it missed records, or the journal was
    /// compacted.
    whole_due: bool,
    /// What was sent and is not answered yet.
    in_flight: Option<Replicate>,
}

impl Replication {
    /// The replication of sensor `sensor`'s journal in the run drawn as
    /// `incarnation`; the standby is not known to be up yet.
    pub fn new(sensor: &str, incarnation: u64) -> Self {
        Replication {
            sensor: sensor.to_string(),
            incarnation,
            epoch: 0,
            present: false,
            reset: 0,
            sent: 0,
            whole_due: true,
            in_flight: None,
        }
    }

    /// The sensor whose journal this replicates.
    pub fn sensor(&self) -> &str {
        &self.sensor
    }

    /// The sensor holds its role at `epoch` from now on: what is sent
    /// next says so. A copy that then holds everything sent is in sync
    /// at it.
    pub fn at_epoch(&mut self, epoch: u64) {
        self.epoch = epoch;
    }

    /// Whether the standby is up as far as the sensor knows.
    pub fn present(&self) -> bool {
        self.present
    }

    /// The standby's liveliness token appeared (`true`) or went away.
    pub fn standby(&mut self, present: bool) -> Option<Presence> {
        if present == self.present {
            return None;
        }
        self.present = present;
        self.in_flight = None;
        // Back or gone, its copy has to be made whole again before an
        // append can follow it.
        self.whole_due = true;
        Some(if present {
            Presence::Back
        } else {
            Presence::Gone
        })
    }

    /// The journal was compacted: its compacted form goes to the standby
    /// next, in place of the appends that led to it.
    pub fn compacted(&mut self) {
        self.whole_due = true;
    }

    /// Records (`appended`, each as the journal holds it) were just
    /// appended to the sensor's journal and fsynced.
    pub fn appended(&mut self, appended: Vec<Vec<u8>>) -> Step {
        if !self.present {
            return Step::Release;
        }
        if self.whole_due {
            return Step::NeedWhole;
        }
        if appended.is_empty() {
            return Step::Release;
        }
        let message = self.message(false, self.sent, appended);
        self.sent += message.records.len() as u64;
        self.in_flight = Some(message.clone());
        Step::Send(message)
    }

    /// The whole journal (`records`, its compacted form) for the standby:
    /// a new reset, which appends then follow.
    pub fn whole(&mut self, records: Vec<Vec<u8>>) -> Replicate {
        self.reset += 1;
        self.sent = records.len() as u64;
        self.whole_due = false;
        let message = self.message(true, 0, records);
        self.in_flight = Some(message.clone());
        message
    }

    /// The standby's answer to what is in flight: its copy's position
    /// (`Some(None)`: it holds nothing of this run), or `None` when it did
    /// not answer in time.
    pub fn answered(&mut self, answer: Option<Option<Position>>) -> Step {
        if !self.present {
            self.in_flight = None;
            return Step::Release;
        }
        let Some(in_flight) = self.in_flight.clone() else {
            return Step::Release;
        };
        match answer {
            // Lost on the way, or slow: the same records again (the copy
            // takes a message it already holds as held).
            None => Step::Send(in_flight),
            Some(Some(at)) if at == self.expected() => {
                self.in_flight = None;
                Step::Release
            }
            // Its copy is elsewhere (it restarted, or missed an append):
            // it is made whole again.
            Some(_) => {
                self.in_flight = None;
                self.whole_due = true;
                Step::NeedWhole
            }
        }
    }

    /// Where the copy is once it holds everything sent.
    fn expected(&self) -> Position {
        Position {
            incarnation: self.incarnation,
            reset: self.reset,
            count: self.sent,
        }
    }

    fn message(&self, whole: bool, first: u64, records: Vec<Vec<u8>>) -> Replicate {
        Replicate {
            version: VERSION,
            sensor: self.sensor.clone(),
            epoch: self.epoch,
            incarnation: self.incarnation,
            reset: self.reset,
            whole,
            first,
            records,
        }
    }
}

/// What the standby does with a [`Replicate`] to its copy.
#[derive(Debug, Clone, PartialEq)]
pub enum Apply<'a> {
    /// Replace the copy by these records (a compaction of it).
    Replace(&'a [Vec<u8>]),
    /// Append these records.
    Append(&'a [Vec<u8>]),
    /// Nothing: held already, or not where the copy is (its answer says
    /// where it is, and the sensor sends the whole journal).
    Nothing,
}

/// The standby's side: where its copy is in the sensor's replication.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Copy {
    /// None: it holds nothing of the sensor's current run (it just
    /// started, or only an earlier run's journal).
    pub position: Option<Position>,
    /// The newest epoch of the sensor role at which the copy held every
    /// record sent (the driver keeps it on disk beside the copy): a
    /// takeover from the copy names it. None: not known.
    pub epoch: Option<u64>,
}

impl Copy {
    /// What to do with `message`; the position moves as if it is done
    /// (the driver answers only once it is on disk).
    pub fn take<'a>(&mut self, message: &'a Replicate) -> Apply<'a> {
        let records = &message.records[..];
        let count = records.len() as u64;
        // From a holder the voters have since superseded (a former sensor
        // not yet stopped): its records are not the role's.
        if self.epoch.is_some_and(|e| message.epoch < e) {
            return Apply::Nothing;
        }
        if message.whole {
            self.position = Some(Position {
                incarnation: message.incarnation,
                reset: message.reset,
                count,
            });
            self.epoch = Some(message.epoch);
            return Apply::Replace(records);
        }
        let Some(at) = &mut self.position else {
            return Apply::Nothing;
        };
        if (at.incarnation, at.reset) != (message.incarnation, message.reset) {
            return Apply::Nothing;
        }
        if at.count == message.first {
            at.count += count;
            // Held whole up to here: in sync at the sender's epoch. (An
            // epoch is never lowered: one process holds it at a time, and
            // a later one starts with a whole journal.)
            self.epoch = self.epoch.max(Some(message.epoch));
            Apply::Append(records)
        } else {
            // Held already (a message sent again), or a gap: either way
            // nothing to write, and the answer says where the copy is.
            Apply::Nothing
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn records(n: u8) -> Vec<Vec<u8>> {
        (0..n).map(|i| vec![i; 3]).collect()
    }

    /// Sends `message` to `copy`, and says where the copy is after.
    fn deliver(copy: &mut Copy, message: &Replicate) -> Option<Position> {
        copy.take(message);
        copy.position
    }

    fn up() -> Replication {
        let mut r = Replication::new("sensor-0", 7);
        assert_eq!(r.standby(true), Some(Presence::Back));
        r
    }

    #[test]
    fn records_are_released_only_once_the_standby_holds_them() {
        let mut r = up();
        let mut copy = Copy::default();
        // The first records need the whole journal first.
        assert_eq!(r.appended(records(2)), Step::NeedWhole);
        let whole = r.whole(records(5));
        assert!(whole.whole && whole.first == 0);
        let at = deliver(&mut copy, &whole);
        assert_eq!(r.answered(Some(at)), Step::Release);
        // Then appends, each released by its own answer and no earlier.
        let Step::Send(first) = r.appended(records(2)) else {
            panic!("an append")
        };
        let Step::Send(second) = r.appended(records(3)) else {
            panic!("an append")
        };
        assert_eq!((first.first, second.first), (5, 7));
        // The copy takes them in order; the answer to the last releases.
        assert_eq!(deliver(&mut copy, &first).map(|p| p.count), Some(7));
        let at = deliver(&mut copy, &second);
        assert_eq!(at.map(|p| p.count), Some(10));
        assert_eq!(r.answered(Some(at)), Step::Release);
    }

    #[test]
    fn an_answer_behind_what_was_sent_releases_nothing() {
        let mut r = up();
        let mut copy = Copy::default();
        let whole = r.whole(records(1));
        let at = deliver(&mut copy, &whole);
        assert_eq!(r.answered(Some(at)), Step::Release);
        let Step::Send(append) = r.appended(records(2)) else {
            panic!("an append")
        };
        // No answer: the same records again, still held.
        assert_eq!(r.answered(None), Step::Send(append.clone()));
        // An answer that does not hold them (the copy restarted): whole.
        let fresh = Copy::default();
        assert_eq!(r.answered(Some(fresh.position)), Step::NeedWhole);
        assert_eq!(r.appended(records(1)), Step::NeedWhole);
    }

    #[test]
    fn without_its_standby_the_sensor_goes_on_alone_and_resyncs_it_when_back() {
        let mut r = Replication::new("sensor-0", 7);
        // Never seen: alone from the start.
        assert_eq!(r.appended(records(3)), Step::Release);
        let mut r = up();
        let mut copy = Copy::default();
        let at = deliver(&mut copy, &r.whole(records(4)));
        assert_eq!(r.answered(Some(at)), Step::Release);
        let Step::Send(_) = r.appended(records(1)) else {
            panic!("an append")
        };
        // Gone while a message was in flight: released, and said once.
        assert_eq!(r.standby(false), Some(Presence::Gone));
        assert_eq!(r.standby(false), None);
        assert_eq!(r.answered(None), Step::Release);
        assert_eq!(r.appended(records(2)), Step::Release);
        // Back: the whole journal first, then appends from its end.
        assert_eq!(r.standby(true), Some(Presence::Back));
        assert_eq!(r.appended(Vec::new()), Step::NeedWhole);
        let whole = r.whole(records(9));
        assert_eq!(whole.reset, 2);
        let at = deliver(&mut copy, &whole);
        assert_eq!(at.map(|p| (p.reset, p.count)), Some((2, 9)));
        assert_eq!(r.answered(Some(at)), Step::Release);
        let Step::Send(next) = r.appended(records(1)) else {
            panic!("an append")
        };
        assert_eq!((next.reset, next.first), (2, 9));
    }

    #[test]
    fn after_a_compaction_the_standby_is_sent_the_compacted_form() {
        let mut r = up();
        let mut copy = Copy::default();
        let at = deliver(&mut copy, &r.whole(records(4)));
        r.answered(Some(at));
        r.compacted();
        assert_eq!(r.appended(records(2)), Step::NeedWhole);
        let whole = r.whole(records(2));
        assert_eq!(copy.take(&whole), Apply::Replace(&whole.records[..]));
        assert_eq!(r.answered(Some(copy.position)), Step::Release);
    }

    #[test]
    fn a_copy_takes_appends_only_where_it_is_and_a_repeat_as_held() {
        let mut r = up();
        let mut copy = Copy::default();
        let whole = r.whole(records(2));
        let Step::Send(append) = r.appended(records(3)) else {
            panic!("an append")
        };
        // Before any whole journal of this run: nothing.
        assert_eq!(copy.take(&append), Apply::Nothing);
        assert_eq!(copy.position, None);
        assert!(matches!(copy.take(&whole), Apply::Replace(_)));
        assert!(matches!(copy.take(&append), Apply::Append(r) if r.len() == 3));
        // The same append again: held, nothing written, same position.
        assert_eq!(copy.take(&append), Apply::Nothing);
        assert_eq!(copy.position.map(|p| p.count), Some(5));
        // Another run's append: nothing.
        let mut other = Replication::new("sensor-0", 8);
        other.standby(true);
        other.whole(records(5));
        let Step::Send(theirs) = other.appended(records(1)) else {
            panic!("an append")
        };
        assert_eq!(copy.take(&theirs), Apply::Nothing);
    }

    #[test]
    fn a_copy_is_in_sync_at_the_epoch_of_what_it_holds_whole() {
        let mut r = up();
        r.at_epoch(3);
        let mut copy = Copy::default();
        let Step::Send(early) = ({
            let at = deliver(&mut copy, &r.whole(records(2)));
            r.answered(Some(at));
            r.appended(records(1))
        }) else {
            panic!("an append")
        };
        assert_eq!((copy.epoch, early.epoch), (Some(3), 3));
        // The sensor moves on (its standby gone): what it sends at the new
        // epoch counts only once the copy holds it whole.
        r.at_epoch(4);
        let Step::Send(gap) = r.appended(records(1)) else {
            panic!("an append")
        };
        assert_eq!(copy.take(&gap), Apply::Nothing);
        assert_eq!(copy.epoch, Some(3), "a copy with a gap is not in sync");
        copy.take(&early);
        copy.take(&gap);
        assert_eq!(copy.epoch, Some(4));
        // A new holder's whole journal replaces the copy; a superseded
        // one's is refused.
        let mut later = Replication::new("sensor-0", 8);
        later.standby(true);
        later.at_epoch(5);
        copy.take(&later.whole(records(1)));
        assert_eq!(copy.epoch, Some(5));
        assert_eq!(copy.take(&r.whole(records(6))), Apply::Nothing);
        assert_eq!(copy.position.map(|p| p.incarnation), Some(8));
    }
}
