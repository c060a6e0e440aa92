//! The replicated map role → (holder, epoch): what a committed command
//! does to it, the same on every voter.
//!
//! A claim of an unheld role takes it at the next epoch. A claim of a
//! role someone else holds must name the epoch it fences off (the
//! claimant saw that holder's lease lapse at that epoch): it takes the
//! role at the next epoch only if that is still the role's epoch, so two
//! takeovers racing for one lapse cannot both win, and a claim made on
//! stale knowledge loses; a claim that names an epoch wins only at that
//! epoch, held or released. A holder's own claim again changes nothing,
//! but a holder may *advance* its role to the next epoch (naming the one
//! it holds), fencing off every claim that names the old one: the sensor
//! does so before it goes on without its standby, whose copy then no
//! longer suffices to take the role over. A release by the holder leaves
//! the role unheld at its epoch, so the next claim raises it. Epochs never
//! go down and never repeat for two holders.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// What a role's entry holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Holding {
    /// The process acting for the role; None: released, nobody.
    pub holder: Option<String>,
    /// Raised at every change of holder; 0 before the first claim.
    pub epoch: u64,
}

/// A command proposed to the voters.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum Command {
    /// `holder` asks for `role`; `fencing` is the epoch of the holder it
    /// replaces (None when it believes the role unheld).
    Claim {
        role: String,
        holder: String,
        fencing: Option<u64>,
    },
    /// `holder` gives `role` up (its process stopping cleanly, or handing
    /// the role home).
    Release { role: String, holder: String },
    /// `holder`, holding `role` at epoch `from`, moves it to the next
    /// epoch: a claim naming `from` loses from then on. (Last, so that
    /// the logs of voters from before it still read.)
    Advance {
        role: String,
        holder: String,
        from: u64,
    },
}

/// What a command did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// The role changed hands (or was released): its new entry.
    Changed { role: String, holding: Holding },
    /// Nothing changed: the claimant holds it already, or the command
    /// named an epoch or a holder that is no longer so.
    Unchanged { role: String, why: &'static str },
}

/// What a voter answers on `query/roles` (JSON): the map its committed
/// log built, with the group's leader and term as it knows them. The
/// leader's map is the newest; a follower's may lag by what it has not
/// yet heard committed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RolesAnswer {
    pub voter: u64,
    /// The group's leader as this voter knows it (0: none).
    pub leader: u64,
    pub term: u64,
    pub roles: Vec<RoleEntry>,
}

/// One role's entry in a [`RolesAnswer`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RoleEntry {
    pub role: String,
    pub holder: Option<String>,
    pub epoch: u64,
}

impl RolesAnswer {
    /// The entry of `role`, if it was ever claimed.
    pub fn get(&self, role: &str) -> Option<&RoleEntry> {
        self.roles.iter().find(|e| e.role == role)
    }

    /// Of the voters' answers, the one to trust: the group leader's own
    /// (it knows every committed claim), the newest term's if several
    /// say they lead (one was deposed and does not know it yet). None
    /// when no voter leads: the group cannot decide now.
    pub fn newest(answers: impl IntoIterator<Item = RolesAnswer>) -> Option<RolesAnswer> {
        answers
            .into_iter()
            .filter(|a| a.leader != 0 && a.leader == a.voter)
            .max_by_key(|a| a.term)
    }
}

/// The replicated map (see the module documentation).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RoleMap {
    roles: BTreeMap<String, Holding>,
}

impl RoleMap {
    /// The entry of `role`, if it was ever claimed.
    pub fn get(&self, role: &str) -> Option<&Holding> {
        self.roles.get(role)
    }

    /// Every role's entry, by role.
    pub fn roles(&self) -> impl Iterator<Item = (&String, &Holding)> {
        self.roles.iter()
    }

    /// Applies a committed command.
    pub fn apply(&mut self, command: &Command) -> Outcome {
        match command {
            Command::Claim {
                role,
                holder,
                fencing,
            } => self.claim(role, holder, *fencing),
            Command::Release { role, holder } => self.release(role, holder),
            Command::Advance { role, holder, from } => self.advance(role, holder, *from),
        }
    }

    fn claim(&mut self, role: &str, holder: &str, fencing: Option<u64>) -> Outcome {
        let unchanged = |why| Outcome::Unchanged {
            role: role.to_string(),
            why,
        };
        let entry = self.roles.get(role);
        let epoch = entry.map_or(0, |h| h.epoch);
        match entry.and_then(|h| h.holder.as_deref()) {
            Some(current) if current == holder => return unchanged("held by the claimant already"),
            Some(_) if fencing != Some(epoch) => {
                return unchanged("held by another at an epoch the claim did not name")
            }
            None if fencing.is_some_and(|f| f != epoch) => {
                return unchanged("released at an epoch the claim did not name")
            }
            _ => {}
        }
        let holding = Holding {
            holder: Some(holder.to_string()),
            epoch: epoch + 1,
        };
        self.roles.insert(role.to_string(), holding.clone());
        Outcome::Changed {
            role: role.to_string(),
            holding,
        }
    }

    fn advance(&mut self, role: &str, holder: &str, from: u64) -> Outcome {
        match self.roles.get_mut(role) {
            Some(h) if h.holder.as_deref() == Some(holder) && h.epoch == from => {
                h.epoch += 1;
                Outcome::Changed {
                    role: role.to_string(),
                    holding: h.clone(),
                }
            }
            _ => Outcome::Unchanged {
                role: role.to_string(),
                why: "advanced by one who does not hold it at that epoch",
            },
        }
    }

    fn release(&mut self, role: &str, holder: &str) -> Outcome {
        match self.roles.get_mut(role) {
            Some(h) if h.holder.as_deref() == Some(holder) => {
                h.holder = None;
                Outcome::Changed {
                    role: role.to_string(),
                    holding: h.clone(),
                }
            }
            _ => Outcome::Unchanged {
                role: role.to_string(),
                why: "released by one who does not hold it",
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn changed(map: &mut RoleMap, command: Command) -> bool {
        matches!(map.apply(&command), Outcome::Changed { .. })
    }

    fn claim(role: &str, holder: &str, fencing: Option<u64>) -> Command {
        Command::Claim {
            role: role.into(),
            holder: holder.into(),
            fencing,
        }
    }

    #[test]
    fn a_takeover_must_name_the_epoch_it_fences_off() {
        let mut map = RoleMap::default();
        assert!(changed(&mut map, claim("leader-1", "a", None)));
        assert_eq!(map.get("leader-1").unwrap().epoch, 1);
        // Blind, or naming an old epoch: refused.
        assert!(!changed(&mut map, claim("leader-1", "b", None)));
        assert!(!changed(&mut map, claim("leader-1", "b", Some(0))));
        // Naming the holder's epoch: taken at the next one.
        assert!(changed(&mut map, claim("leader-1", "b", Some(1))));
        assert_eq!(
            map.get("leader-1").unwrap(),
            &Holding {
                holder: Some("b".into()),
                epoch: 2
            }
        );
        // A second claimant that saw the same lapse loses the race.
        assert!(!changed(&mut map, claim("leader-1", "c", Some(1))));
        // The holder's own claim again changes nothing.
        assert!(!changed(&mut map, claim("leader-1", "b", Some(2))));
        assert_eq!(map.get("leader-1").unwrap().epoch, 2);
    }

    #[test]
    fn a_released_role_is_claimed_at_a_higher_epoch() {
        let mut map = RoleMap::default();
        map.apply(&claim("sensor-0", "a", None));
        let stranger = Command::Release {
            role: "sensor-0".into(),
            holder: "b".into(),
        };
        assert!(matches!(map.apply(&stranger), Outcome::Unchanged { .. }));
        let release = Command::Release {
            role: "sensor-0".into(),
            holder: "a".into(),
        };
        assert!(matches!(map.apply(&release), Outcome::Changed { .. }));
        assert_eq!(map.get("sensor-0").unwrap().holder, None);
        map.apply(&claim("sensor-0", "a", None));
        assert_eq!(map.get("sensor-0").unwrap().epoch, 2);
    }

    #[test]
    fn a_holder_advancing_fences_off_claims_on_its_old_epoch() {
        let mut map = RoleMap::default();
        map.apply(&claim("sensor-0", "a", None));
        let advance = |holder: &str, from| Command::Advance {
            role: "sensor-0".into(),
            holder: holder.into(),
            from,
        };
        // Only the holder, and only from the epoch it holds.
        assert!(!changed(&mut map, advance("b", 1)));
        assert!(!changed(&mut map, advance("a", 0)));
        assert!(changed(&mut map, advance("a", 1)));
        assert_eq!(
            map.get("sensor-0").unwrap(),
            &Holding {
                holder: Some("a".into()),
                epoch: 2
            }
        );
        // A standby whose copy was in sync at epoch 1 can no longer win,
        // nor once the role is released at epoch 2.
        assert!(!changed(&mut map, claim("sensor-0", "b", Some(1))));
        map.apply(&Command::Release {
            role: "sensor-0".into(),
            holder: "a".into(),
        });
        assert!(!changed(&mut map, claim("sensor-0", "b", Some(1))));
        assert!(changed(&mut map, claim("sensor-0", "b", Some(2))));
        assert_eq!(map.get("sensor-0").unwrap().epoch, 3);
    }
}
