//! Which of a sensor role's standbys its holder replicates to, as a pure
//! state machine: the driver (`crate::standby`) feeds it the standbys'
//! liveliness tokens and the role's advances, and moves the bytes.
//!
//! A sensor role may have several standbys, in the topology's order. Its
//! holder replicates to one at a time ([`crate::machine::replication`]
//! knows one copy): the first present, kept while it stays present (a
//! standby that comes back does not take over from one that holds the
//! journal already). When that one goes, another is chosen.
//!
//! The rule that keeps a takeover safe: at most one copy is in sync at
//! the role's current epoch. A copy is in sync at the epoch of what it
//! holds whole, and a takeover names that epoch; so before the holder
//! releases anything a standby that went did not acknowledge, the role
//! moves to a new epoch ([`Standbys::fence_due`]; the driver asks the
//! voters), and only then is the next standby chosen and sent the whole
//! journal at that epoch. A copy left behind, even one merely cut off
//! from the holder, then names an epoch the role has moved past, and
//! loses its claim. For the same reason a holding that starts with more
//! than one standby moves the role on before it chooses: an earlier run of
//! the role may have left another copy in sync at the epoch it holds.
//! Without voters nothing takes the role over, and no fence is owed.

/// What changed for the replication.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Change {
    /// The standby replicated to went: the holder goes on without one.
    Gone(String),
    /// This standby is replicated to from now on (it gets the whole
    /// journal first).
    Chosen(String),
}

/// The standby a fence is owed for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Owed {
    /// Candidate `i` went while replicated to, and nothing was released
    /// since: it may come back and be chosen again without a fence.
    Went(usize),
    /// Not known (the holding just started): an earlier run may have
    /// replicated to any of them.
    Unknown,
}

/// A role's standbys and the one replicated to.
#[derive(Debug, Clone)]
pub struct Standbys {
    /// In the topology's order.
    candidates: Vec<String>,
    present: Vec<bool>,
    current: Option<usize>,
    /// With voters, the fence owed before the next standby is chosen.
    owed: Option<Owed>,
    fencing: bool,
}

impl Standbys {
    /// `candidates` in order of preference; `fencing`: the role is held
    /// through voters (a standby may take it over).
    pub fn new(candidates: Vec<String>, fencing: bool) -> Self {
        let owed = (fencing && candidates.len() > 1).then_some(Owed::Unknown);
        Standbys {
            present: vec![false; candidates.len()],
            candidates,
            current: None,
            owed,
            fencing,
        }
    }

    /// The standby replicated to, if any.
    pub fn current(&self) -> Option<&str> {
        self.current.map(|i| self.candidates[i].as_str())
    }

    /// Whether `name` is one of the role's standbys.
    pub fn knows(&self, name: &str) -> bool {
        self.candidates.iter().any(|c| c == name)
    }

    /// The token of standby `name` appeared (`present`) or went: what
    /// changed for the replication, in order.
    pub fn token(&mut self, name: &str, present: bool) -> Vec<Change> {
        let Some(i) = self.candidates.iter().position(|c| c == name) else {
            return Vec::new();
        };
        self.present[i] = present;
        let mut changes = Vec::new();
        if !present && self.current == Some(i) {
            self.current = None;
            changes.push(Change::Gone(name.to_string()));
            if self.fencing {
                self.owed = Some(Owed::Went(i));
            }
        }
        if present && self.owed == Some(Owed::Went(i)) {
            // Back before anything was released without it: its copy is
            // still the one in sync.
            self.owed = None;
            self.current = Some(i);
            changes.push(Change::Chosen(name.to_string()));
            return changes;
        }
        changes.extend(self.choose());
        changes
    }

    /// Whether a fence is owed and the holder has a standby to choose
    /// once it is made (the driver then fences at once, not at the next
    /// record).
    pub fn waiting(&self) -> bool {
        self.owed.is_some() && self.present.iter().any(|&p| p)
    }

    /// Whether the role must move to a new epoch before anything more is
    /// released: a standby went (or the holding just started among
    /// several), and no other is chosen yet.
    pub fn fence_due(&self) -> bool {
        self.owed.is_some()
    }

    /// The role moved to a new epoch since the fence was owed: the next
    /// standby present, if any, is chosen.
    pub fn fenced(&mut self) -> Option<Change> {
        self.owed = None;
        self.choose()
    }

    /// The first standby present, while none is replicated to and no
    /// fence is owed.
    fn choose(&mut self) -> Option<Change> {
        if self.current.is_some() || self.owed.is_some() {
            return None;
        }
        let i = self.present.iter().position(|&p| p)?;
        self.current = Some(i);
        Some(Change::Chosen(self.candidates[i].clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: &[&str]) -> Vec<String> {
        n.iter().map(|s| s.to_string()).collect()
    }

    fn chosen(name: &str) -> Change {
        Change::Chosen(name.to_string())
    }

    #[test]
    fn one_standby_without_voters_is_chosen_whenever_present() {
        let mut s = Standbys::new(names(&["a"]), false);
        assert_eq!(s.token("a", true), vec![chosen("a")]);
        assert_eq!(s.token("a", false), vec![Change::Gone("a".into())]);
        assert!(!s.fence_due());
        assert_eq!(s.token("a", true), vec![chosen("a")]);
        // Not a standby of this role: nothing.
        assert_eq!(s.token("z", true), Vec::new());
    }

    #[test]
    fn one_standby_with_voters_owes_a_fence_only_once_it_went() {
        let mut s = Standbys::new(names(&["a"]), true);
        assert!(!s.fence_due(), "a single standby is the only copy");
        assert_eq!(s.token("a", true), vec![chosen("a")]);
        s.token("a", false);
        assert!(s.fence_due());
        // Back before a release: chosen again, no fence.
        assert_eq!(s.token("a", true), vec![chosen("a")]);
        assert!(!s.fence_due());
        s.token("a", false);
        assert_eq!(s.fenced(), None);
        assert_eq!(s.token("a", true), vec![chosen("a")]);
    }

    #[test]
    fn the_choice_is_sticky_and_a_switch_waits_for_the_fence() {
        let mut s = Standbys::new(names(&["a", "b", "c"]), true);
        // A holding among several starts owing a fence.
        assert_eq!(s.token("b", true), Vec::new());
        assert!(s.waiting());
        assert_eq!(s.fenced(), Some(chosen("b")));
        // a comes up: b keeps the journal.
        assert_eq!(s.token("a", true), Vec::new());
        assert_eq!(s.current(), Some("b"));
        // b goes: nothing chosen until the role moved on.
        assert_eq!(s.token("b", false), vec![Change::Gone("b".into())]);
        assert_eq!(s.current(), None);
        assert!(s.fence_due() && s.waiting());
        // Another's token meanwhile chooses nothing either.
        assert_eq!(s.token("c", true), Vec::new());
        assert_eq!(s.fenced(), Some(chosen("a")));
        // b back: a keeps it.
        assert_eq!(s.token("b", true), Vec::new());
        assert_eq!(s.current(), Some("a"));
    }

    #[test]
    fn without_voters_a_switch_is_immediate() {
        let mut s = Standbys::new(names(&["a", "b"]), false);
        assert!(!s.fence_due());
        s.token("a", true);
        s.token("b", true);
        assert_eq!(
            s.token("a", false),
            vec![Change::Gone("a".into()), chosen("b")]
        );
        assert_eq!(s.current(), Some("b"));
    }

    #[test]
    fn with_none_present_the_fence_still_releases() {
        let mut s = Standbys::new(names(&["a", "b"]), true);
        assert!(s.fence_due() && !s.waiting());
        assert_eq!(s.fenced(), None);
        assert!(!s.fence_due());
        assert_eq!(s.token("b", true), vec![chosen("b")]);
    }
}
