//! Links between groups: what a lossy cut keeps of the assignments it
//! would otherwise rule out.
//!
//! A hard cut of a group into (A, I_A) and (B, I_B) conditions on E =
//! {π(A) = I_A}: the assignments that send an identity of I_A to B are set
//! to 0, and no later read can bring them back. A *linked* cut keeps, in
//! each factor, the event that one identity crossed: side A gets a port —
//! a phantom track φ_A and a star identity *_A, both named by the port's
//! id — and so does side B. On A, "track a carries *_A" means a carries
//! the identity of B that crossed, and "φ_A carries x" means identity x of
//! A is the one on B; φ_A carrying *_A means nothing crossed. The two
//! sides agree on the exchange flag e (whether something crossed), and
//! the joint is
//!
//!   q(π) ∝ Π_groups f_G(σ_G) · Π_links [e_A = e_B],
//!
//! a tree of factors whose separators are the binary flags: given e the
//! two sides are independent. This is Huang, Guestrin and Guibas's
//! riffled independence (*Riffled Independence for Ranked Data*, NIPS
//! 2009, Section 3: a distribution over which of the items go to which
//! side, the "interleaving", times the two sides' relative rankings),
//! restricted to interleavings at most one exchange from the cut's and
//! with the sides allowed to depend on the interleaving through e. The
//! cut (see [`super::split::apply_linked`]) is the M-projection of the
//! group onto that family: f_A(σ_A) = P(σ_A, e), f_B(σ_B) = P(σ_B | e),
//! losing the mass of two or more exchanges (or of an identity that would
//! cross two links) and I(σ_A; σ_B | e).
//!
//! On that representation:
//!
//! - mixes of real tracks and reads of an identity of the track's group
//!   act on one factor and are exact (the flags of a group do not change
//!   under a mix of its real tracks);
//! - a read of an identity across a link (track t of G reads identity y of
//!   the linked group H) has a likelihood that couples the two factors
//!   through two binary features (t carries *_G; φ_H carries y); it is
//!   applied by assumed density filtering — each factor gets the exact
//!   posterior marginal of its side, the H factor divided by the flag's
//!   likelihood so that the link's flag is not counted twice — so the
//!   posterior is the M-projection of the exact update onto the tree
//!   family (exact group beliefs and flag marginals);
//! - a join of two linked groups collapses the link exactly (a track
//!   carrying *_A gets what φ_B carries, and the other way round); a join
//!   of two groups of one tree not linked directly would close a cycle,
//!   so the link on the path between them with the least exchange
//!   probability is dropped first (conditioning on e = 0, a loss of
//!   P(e = 1));
//! - a link whose exchange probability falls below `certain` after a read
//!   is dropped the same way;
//! - marginals are computed by belief propagation over each tree (the
//!   messages are 2-vectors over a flag), and a track's mass on a star is
//!   spread over the partner's identities by its phantom's distribution
//!   given e = 1.

use super::group::{config_weights, Group, Port};
use super::split::{self, Cut};
use super::FactoredIdentity;
use idmesh_belief::BeliefError;
use std::collections::HashMap;

/// Belief propagation over the trees of linked groups, with its messages
/// cached for one state of the belief.
pub(crate) struct Messages<'a> {
    belief: &'a FactoredIdentity,
    /// Message into the group holding port p, over p's flag.
    into: HashMap<u32, [f64; 2]>,
}

impl<'a> Messages<'a> {
    pub(crate) fn new(belief: &'a FactoredIdentity) -> Self {
        Messages {
            belief,
            into: HashMap::new(),
        }
    }

    /// The message into port p's group from across p's link: the partner
    /// side's mass by flag, with the messages of its other links.
    pub(crate) fn toward_port(&mut self, p: u32) -> [f64; 2] {
        if let Some(&m) = self.into.get(&p) {
            return m;
        }
        let b = self.belief;
        let q = b.partner(p);
        let h = b.group_of[q as usize];
        let ports = b.groups[h].ports(b.n);
        let flags = b.groups[h].flag_table(&ports);
        let messages: Vec<[f64; 2]> = ports
            .iter()
            .map(|port| {
                if port.id == q {
                    [1.0, 1.0]
                } else {
                    self.toward_port(port.id)
                }
            })
            .collect();
        let weights = config_weights(ports.len(), &messages);
        let i = ports.iter().position(|port| port.id == q).unwrap_or(0);
        let mut m = [0.0; 2];
        for (c, (&f, &w)) in flags.iter().zip(&weights).enumerate() {
            m[(c >> i) & 1] += f * w;
        }
        let total = m[0] + m[1];
        if total > 0.0 && total.is_finite() {
            m[0] /= total;
            m[1] /= total;
        }
        self.into.insert(p, m);
        m
    }

    /// The messages into group g, one per port in local order.
    pub(crate) fn toward_group(&mut self, g: usize) -> (Vec<Port>, Vec<[f64; 2]>) {
        let ports = self.belief.groups[g].ports(self.belief.n);
        let messages = ports.iter().map(|p| self.toward_port(p.id)).collect();
        (ports, messages)
    }

    /// The local marginals of group g's belief (its factor times the
    /// messages): rows of phantoms and columns of stars included.
    pub(crate) fn group_marginals(&mut self, g: usize) -> Result<Vec<Vec<f64>>, BeliefError> {
        let (ports, messages) = self.toward_group(g);
        self.belief.groups[g]
            .weighted_marginals(&ports, &messages)
            .ok_or(BeliefError::Degenerate { normalizer: 0.0 })
    }
}

/// P(e = 1) of a port from its group's local marginals.
fn exchange_probability(m: &[Vec<f64>], port: &Port) -> f64 {
    (1.0 - m[port.phantom][port.star]).clamp(0.0, 1.0)
}

impl FactoredIdentity {
    /// The other end of port p's link.
    pub(crate) fn partner(&self, p: u32) -> u32 {
        let local = p as usize - self.n;
        (self.n + (local ^ 1)) as u32
    }

    /// A fresh link: its two port ids (side A, side B).
    pub(crate) fn new_link(&mut self) -> (u32, u32) {
        let slot = match self.link_used.iter().position(|&u| !u) {
            Some(s) => s,
            None => {
                self.link_used.push(false);
                self.link_used.len() - 1
            }
        };
        self.link_used[slot] = true;
        let need = self.n + 2 * self.link_used.len();
        if self.group_of.len() < need {
            self.group_of.resize(need, usize::MAX);
        }
        let pa = (self.n + 2 * slot) as u32;
        (pa, pa + 1)
    }

    /// The ports on the path of links from group `from` to group `to`,
    /// each named by its end nearer `from`; `None` if not linked at all.
    pub(crate) fn path(&self, from: usize, to: usize) -> Option<Vec<u32>> {
        // Breadth-first over the tree: came[g] = (port into g, previous).
        let mut came: HashMap<usize, (u32, usize)> = HashMap::new();
        let mut queue = std::collections::VecDeque::from([from]);
        let mut seen = std::collections::HashSet::from([from]);
        while let Some(g) = queue.pop_front() {
            if g == to {
                let mut path = Vec::new();
                let mut at = to;
                while at != from {
                    let (port, prev) = came[&at];
                    path.push(self.partner(port));
                    at = prev;
                }
                path.reverse();
                return Some(path);
            }
            for port in self.groups[g].ports(self.n) {
                let q = self.partner(port.id);
                let h = self.group_of[q as usize];
                if seen.insert(h) {
                    came.insert(h, (q, g));
                    queue.push_back(h);
                }
            }
        }
        None
    }

    /// P(e = 1) of port p's link under the belief.
    pub(crate) fn exchange(&self, p: u32) -> Result<f64, BeliefError> {
        let g = self.group_of[p as usize];
        let m = Messages::new(self).group_marginals(g)?;
        let port = self.groups[g].port(self.n, p)?;
        Ok(exchange_probability(&m, &port))
    }

    /// Drops port p's link by conditioning both sides on e = 0 (nothing
    /// crossed), losing P(e = 1) = `lost`.
    pub(crate) fn drop_link(&mut self, p: u32, lost: f64) -> Result<(), BeliefError> {
        let q = self.partner(p);
        let mut new = Vec::new();
        let mut old = Vec::new();
        for id in [p, q] {
            let g = self.group_of[id as usize];
            let group = &self.groups[g];
            let j = group.local_track(id).unwrap_or(usize::MAX);
            let x = group.identities.iter().position(|&i| i == id);
            let (Some(x), true) = (x, j < group.size()) else {
                return Err(BeliefError::BadComponent {
                    detail: format!("port {id} is not in its group"),
                });
            };
            let cut = Cut {
                tracks: 1 << j,
                identities: 1 << x,
                mass: 1.0,
                mutual_information: 0.0,
            };
            old.push(g);
            // Ruled out: the assignments in which a real track carries the
            // star (something crossed).
            let m = group.local_marginals();
            let lost: Vec<(usize, f64)> = (0..group.size())
                .filter(|&k| k != j)
                .map(|k| (group.tracks[k] as usize, m[k][x]))
                .collect();
            if group.size() > 1 {
                let (_, rest) = split::apply(group, &cut)?;
                new.push(rest);
            }
            for (t, q) in lost {
                if let Some(background) = self.backgrounds.get_mut(t) {
                    background.lose(q);
                }
            }
        }
        self.replace(old, new);
        self.group_of[p as usize] = usize::MAX;
        self.group_of[q as usize] = usize::MAX;
        self.link_used[(p as usize - self.n) / 2] = false;
        self.stats.dropped_links += 1;
        self.add_loss(lost, 0.0);
        Ok(())
    }

    /// Drops every link of the group holding `track` whose exchange
    /// probability is below `certain` (a loss of at most `certain` each).
    pub(crate) fn prune_links(&mut self, track: u32) -> Result<(), BeliefError> {
        loop {
            let g = self.group_of[track as usize];
            let ports = self.groups[g].ports(self.n);
            if ports.is_empty() {
                return Ok(());
            }
            let m = Messages::new(self).group_marginals(g)?;
            let weakest = ports
                .iter()
                .map(|p| (exchange_probability(&m, p), p.id))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            match weakest {
                Some((e, id)) if e <= self.options.certain => self.drop_link(id, e)?,
                _ => return Ok(()),
            }
        }
    }

    /// Collapses every link both of whose ports are in group g: exact (the
    /// joint restricted to agreeing flags, a track on a star given what the
    /// other side's phantom carries).
    pub(crate) fn collapse(group: &Group, n: usize) -> Result<(Group, Vec<u32>), BeliefError> {
        let mut group = group.clone();
        let mut freed = Vec::new();
        loop {
            let ports = group.ports(n);
            let pair = ports.iter().find_map(|p| {
                let partner = (n + ((p.id as usize - n) ^ 1)) as u32;
                ports.iter().find(|q| q.id == partner).map(|q| (*p, *q))
            });
            let Some((p, q)) = pair else {
                return Ok((group, freed));
            };
            let k = group.size();
            let keep_t: Vec<usize> = (0..k)
                .filter(|&j| j != p.phantom && j != q.phantom)
                .collect();
            let keep_x: Vec<usize> = (0..k).filter(|&x| x != p.star && x != q.star).collect();
            let mut new_x = vec![u8::MAX; k];
            for (i, &x) in keep_x.iter().enumerate() {
                new_x[x] = i as u8;
            }
            let tracks = keep_t.iter().map(|&j| group.tracks[j]).collect();
            let identities = keep_x.iter().map(|&x| group.identities[x]).collect();
            let (collapsed, _) = group.relabel(tracks, identities, |perm, out| {
                let ep = perm[p.phantom] as usize != p.star;
                let eq = perm[q.phantom] as usize != q.star;
                if ep != eq {
                    return false;
                }
                for (slot, &j) in out.iter_mut().zip(&keep_t) {
                    let x = perm[j] as usize;
                    *slot = if x == p.star {
                        // Carries what crossed from q's side.
                        new_x[perm[q.phantom] as usize]
                    } else if x == q.star {
                        new_x[perm[p.phantom] as usize]
                    } else {
                        new_x[x]
                    };
                }
                // A phantom carrying the other star would be an identity
                // crossing twice; never built, dropped if met.
                out.iter().all(|&x| x != u8::MAX)
            })?;
            freed.push(p.id.min(q.id));
            group = collapsed;
        }
    }

    /// A read on track t (local `track` of group g) of identity y of the
    /// group linked to g through port `p`: assumed density filtering (see
    /// the module docs).
    pub(crate) fn read_across(
        &mut self,
        g: usize,
        track: usize,
        p: u32,
        y: u32,
        right: f64,
        wrong: f64,
    ) -> Result<(), BeliefError> {
        let q = self.partner(p);
        let h = self.group_of[q as usize];
        let (mg, mh) = {
            let mut bp = Messages::new(self);
            (bp.group_marginals(g)?, bp.group_marginals(h)?)
        };
        let port_g = self.groups[g].port(self.n, p)?;
        let port_h = self.groups[h].port(self.n, q)?;
        let yl = self.groups[h]
            .identities
            .iter()
            .position(|&i| i == y)
            .ok_or(BeliefError::BadComponent {
                detail: format!("identity {y} is not in its group"),
            })?;
        let given = |m: &[Vec<f64>], port: &Port, row: usize, col: usize| {
            let e = exchange_probability(m, port);
            if e > 0.0 {
                (m[row][col] / e).clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        // c = P(φ_H carries y | e), d = P(t carries *_G | e).
        let c = given(&mh, &port_h, port_h.phantom, yl);
        let d = given(&mg, &port_g, track, port_g.star);
        let lift = right - wrong;
        let (mut fg, mut fh) = (self.groups[g].clone(), self.groups[h].clone());
        let star = port_g.star as u8;
        fg.reweight(|perm| {
            if perm[track] == star {
                wrong + lift * c
            } else {
                wrong
            }
        })?;
        let (phantom, star_h, yl) = (port_h.phantom, port_h.star as u8, yl as u8);
        let crossed = wrong + lift * c * d;
        fh.reweight(|perm| {
            let carried = if perm[phantom] == yl {
                wrong + lift * d
            } else {
                wrong
            };
            let flag = if perm[phantom] != star_h {
                crossed
            } else {
                wrong
            };
            if flag > 0.0 {
                carried / flag
            } else {
                0.0
            }
        })?;
        self.groups[g] = fg;
        self.groups[h] = fh;
        Ok(())
    }
}
