//! Cutting a group in two when a mix would join groups into one larger
//! than the cap: the split step of split/join identity filters (Huang,
//! Guestrin and Guibas, *Efficient Inference for Distributions on
//! Permutations*, NIPS 2007, and their riffled-independence work, JMLR
//! 2012), in its simplest form: a cut is a set A of the group's tracks
//! together with a set I_A of as many identities, and the group is
//! replaced by the two factors
//!
//!   p_A(σ) = P(σ on A | π(A) = I_A),  p_B(τ) = P(τ on B | π(A) = I_A),
//!
//! the marginals of the belief conditioned on the event E = {π(A) = I_A}
//! (moment matching onto the family of products over the partition
//! (A, I_A) ∪ (B, I_B), after conditioning). Two things are lost: the mass
//! 1 − P(E) of the assignments that send an identity of I_A outside A, and
//! the mutual information between the assignments on A and on B given E.
//! A cut costs
//!
//!   cost = (1 − P(E)) + I(σ; τ | E)   (nats),
//!
//! 0 exactly when the split is exact (E is sure and the two sides are
//! independent under it — e.g. a track whose identity is certain).
//!
//! For every size s the cut of largest P(E) among those whose A holds a
//! given track of size s is found in one pass over the assignments of
//! non-zero probability (at most k!), accumulating P(π(A) = I) for every
//! A that holds the track (O(k!·2^(k−1)) at most); the mutual information
//! is then computed for that one cut per size. The factors are built from
//! (rank, probability) entries summed by rank in the order the dense code
//! added them, and stored sparsely or densely ([`super::assignments`]).

use super::assignments::{accumulate, lookup, Assignments};
use super::group::{permutations, Group, Port, MAX_GROUP};
use idmesh_belief::BeliefError;

/// A cut of a group: local tracks A (bit j = local track j) and the local
/// identities I_A (bit x) they are taken to carry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cut {
    pub tracks: u32,
    pub identities: u32,
    /// P(π(A) = I_A).
    pub mass: f64,
    /// I(σ; τ | E), nats.
    pub mutual_information: f64,
}

impl Cut {
    /// What the cut loses: (1 − P(E)) + I(σ; τ | E).
    pub(crate) fn cost(&self) -> f64 {
        (1.0 - self.mass).max(0.0) + self.mutual_information.max(0.0)
    }

    /// |A|.
    pub fn size(&self) -> usize {
        self.tracks.count_ones() as usize
    }
}

/// Assignments of probability below this are left out of the search for
/// cuts: they cannot change which cut is best by more than their total.
const NEGLIGIBLE: f64 = 1e-18;

/// For every s in 1..k (k the group's size), the cut of largest mass whose
/// A holds local track `keep` and has s tracks: `result[s]` (index 0 and k
/// are `None`). Ties go to the first cut met, which is deterministic. A
/// cut keeps each port's phantom track and star identity on one side.
pub(crate) fn best_cuts(group: &Group, keep: usize, must: u32, ports: &[Port]) -> Vec<Option<Cut>> {
    let k = group.size();
    let mut best: Vec<Option<Cut>> = vec![None; k + 1];
    if k < 2 {
        return best;
    }
    let table = group.table();
    let others: Vec<usize> = (0..k).filter(|&j| j != keep).collect();
    let subsets = 1usize << (k - 1);
    let mut mass = vec![0.0f64; subsets << k];
    let mut image = vec![0u32; subsets];
    for (r, p) in group.entries() {
        if p < NEGLIGIBLE {
            continue;
        }
        let perm = table.get(r as usize);
        image[0] = 1 << perm[keep];
        mass[image[0] as usize] += p;
        for s in 1..subsets {
            let low = s.trailing_zeros() as usize;
            image[s] = image[s & (s - 1)] | (1 << perm[others[low]]);
            mass[(s << k) | image[s] as usize] += p;
        }
    }
    for s in 0..subsets {
        let size = s.count_ones() as usize + 1;
        if size >= k {
            continue;
        }
        let row = &mass[s << k..(s + 1) << k];
        let holds = others
            .iter()
            .enumerate()
            .filter(|&(bit, _)| s & (1 << bit) != 0)
            .fold(1u32 << keep, |acc, (_, &j)| acc | (1 << j));
        if holds & must != must {
            continue;
        }
        let tracks = others
            .iter()
            .enumerate()
            .filter(|&(bit, _)| s & (1 << bit) != 0)
            .fold(1u32 << keep, |acc, (_, &j)| acc | (1 << j));
        for (identities, &m) in row.iter().enumerate() {
            let whole_ports = ports
                .iter()
                .all(|p| (tracks >> p.phantom) & 1 == ((identities as u32) >> p.star) & 1);
            if whole_ports && m > best[size].map_or(0.0, |c| c.mass) {
                best[size] = Some(Cut {
                    tracks,
                    identities: identities as u32,
                    mass: m,
                    mutual_information: 0.0,
                });
            }
        }
    }
    for cut in best.iter_mut().flatten() {
        // Both factors are built only to measure what the cut loses.
        if let Ok((a, b)) = apply(group, cut) {
            cut.mutual_information = mutual_information(group, cut, &a, &b);
        }
    }
    best
}

/// Where an assignment of the group goes under a cut: the rank of its
/// restriction to A (in A's table) and to B, or `None` outside E.
struct Projector {
    a_tracks: Vec<usize>,
    b_tracks: Vec<usize>,
    /// position[x] = index of local identity x within its side's list.
    position: Vec<u8>,
    identities: u32,
    a_table: &'static crate::permutation::Permutations,
    b_table: &'static crate::permutation::Permutations,
}

impl Projector {
    fn new(group: &Group, cut: &Cut) -> Result<Self, BeliefError> {
        let k = group.size();
        let a_tracks: Vec<usize> = (0..k).filter(|&j| cut.tracks & (1 << j) != 0).collect();
        let b_tracks: Vec<usize> = (0..k).filter(|&j| cut.tracks & (1 << j) == 0).collect();
        let mut position = vec![0u8; k];
        let (mut na, mut nb) = (0u8, 0u8);
        for (x, slot) in position.iter_mut().enumerate() {
            if cut.identities & (1 << x) != 0 {
                *slot = na;
                na += 1;
            } else {
                *slot = nb;
                nb += 1;
            }
        }
        if na as usize != a_tracks.len() || a_tracks.is_empty() || b_tracks.is_empty() {
            return Err(BeliefError::BadComponent {
                detail: format!(
                    "a cut of {} tracks and {na} identities of a group of {k}",
                    a_tracks.len()
                ),
            });
        }
        Ok(Projector {
            a_table: permutations(a_tracks.len())?,
            b_table: permutations(b_tracks.len())?,
            a_tracks,
            b_tracks,
            position,
            identities: cut.identities,
        })
    }

    /// The ranks (on A, on B) of an assignment of the group, if it is in E.
    fn project(&self, perm: &[u8]) -> Option<(usize, usize)> {
        let mut a = [0u8; MAX_GROUP];
        let mut b = [0u8; MAX_GROUP];
        for (slot, &j) in a.iter_mut().zip(&self.a_tracks) {
            let x = perm[j];
            if self.identities & (1 << x) == 0 {
                return None;
            }
            *slot = self.position[x as usize];
        }
        for (slot, &j) in b.iter_mut().zip(&self.b_tracks) {
            *slot = self.position[perm[j] as usize];
        }
        Some((
            self.a_table.rank(&a[..self.a_tracks.len()]),
            self.b_table.rank(&b[..self.b_tracks.len()]),
        ))
    }
}

/// The two factors of a cut: the group on A (with I_A) and on B (with the
/// other identities), each the marginal of the belief conditioned on E.
pub fn apply(group: &Group, cut: &Cut) -> Result<(Group, Group), BeliefError> {
    let projector = Projector::new(group, cut)?;
    let table = group.table();
    let (mut pa, mut pb) = (Vec::new(), Vec::new());
    for (r, p) in group.entries() {
        if let Some((ra, rb)) = projector.project(table.get(r as usize)) {
            pa.push((ra as u32, p));
            pb.push((rb as u32, p));
        }
    }
    let (mut pa, mut pb) = (accumulate(pa), accumulate(pb));
    let mass: f64 = pa.iter().map(|e| e.1).sum();
    if !(mass.is_finite() && mass > 0.0) {
        return Err(BeliefError::Degenerate { normalizer: mass });
    }
    pa.iter_mut().for_each(|e| e.1 /= mass);
    pb.iter_mut().for_each(|e| e.1 /= mass);
    let side = |tracks: &[usize], inside: bool, count: usize, probs| Group {
        tracks: tracks.iter().map(|&j| group.tracks[j]).collect(),
        identities: (0..group.size())
            .filter(|&x| (cut.identities & (1 << x) != 0) == inside)
            .map(|x| group.identities[x])
            .collect(),
        probs: Assignments::from_sorted(count, probs),
    };
    Ok((
        side(&projector.a_tracks, true, projector.a_table.count(), pa),
        side(&projector.b_tracks, false, projector.b_table.count(), pb),
    ))
}

/// I(σ; τ | E) in nats, given the two factors of the cut.
fn mutual_information(group: &Group, cut: &Cut, a: &Group, b: &Group) -> f64 {
    let Ok(projector) = Projector::new(group, cut) else {
        return f64::INFINITY;
    };
    if cut.mass.is_nan() || cut.mass <= 0.0 {
        return f64::INFINITY;
    }
    let table = group.table();
    let mut info = 0.0;
    for (r, p) in group.entries() {
        if let Some((ra, rb)) = projector.project(table.get(r as usize)) {
            let joint = p / cut.mass;
            info += joint * (joint / (a.probability(ra as u32) * b.probability(rb as u32))).ln();
        }
    }
    info.max(0.0)
}

/// A linked cut of a group (see [`super::links`]): the two factors, each
/// with a new port, and what the cut loses.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LinkedCut {
    /// The factor on A and I_A, with port `pa`.
    pub a: Group,
    /// The factor on B and I_B, with port `pb`.
    pub b: Group,
    /// The mass kept: assignments with at most one identity across the
    /// cut, neither a port's.
    pub mass: f64,
    /// I(σ_A; σ_B | e) of the kept part, nats.
    pub mutual_information: f64,
}

impl LinkedCut {
    /// (1 − kept mass) + I(σ_A; σ_B | e).
    pub(crate) fn cost(&self) -> f64 {
        (1.0 - self.mass).max(0.0) + self.mutual_information.max(0.0)
    }
}

/// Where an assignment of the group goes under a linked cut.
struct LinkedProjector {
    a_tracks: Vec<usize>,
    b_tracks: Vec<usize>,
    position: Vec<u8>,
    identities: u32,
    /// Bit j: local track j is a phantom; bit x: local identity x a star.
    phantom_tracks: u32,
    star_identities: u32,
    a_table: &'static crate::permutation::Permutations,
    b_table: &'static crate::permutation::Permutations,
}

impl LinkedProjector {
    fn new(group: &Group, cut: &Cut, ports: &[Port]) -> Result<Self, BeliefError> {
        let plain = Projector::new(group, cut)?;
        let (na, nb) = (plain.a_tracks.len(), plain.b_tracks.len());
        if na + 1 > MAX_GROUP || nb + 1 > MAX_GROUP {
            return Err(BeliefError::BadComponent {
                detail: format!("a linked cut into {na} and {nb} tracks"),
            });
        }
        Ok(LinkedProjector {
            a_table: permutations(na + 1)?,
            b_table: permutations(nb + 1)?,
            phantom_tracks: ports.iter().fold(0, |m, p| m | (1 << p.phantom)),
            star_identities: ports.iter().fold(0, |m, p| m | (1 << p.star)),
            a_tracks: plain.a_tracks,
            b_tracks: plain.b_tracks,
            position: plain.position,
            identities: plain.identities,
        })
    }

    /// The ranks (on A + port, on B + port) and the exchange flag of an
    /// assignment, or `None` if the linked cut drops it.
    fn project(&self, perm: &[u8]) -> Option<(usize, usize, bool)> {
        let in_a = |x: u8| self.identities & (1 << x) != 0;
        let (na, nb) = (self.a_tracks.len(), self.b_tracks.len());
        let mut a = [0u8; MAX_GROUP];
        let mut b = [0u8; MAX_GROUP];
        // The A track carrying an identity of B, and the B track carrying
        // one of A: at most one each (then both or neither).
        let mut across_a: Option<(usize, u8)> = None;
        for (slot, &j) in a.iter_mut().zip(&self.a_tracks) {
            let x = perm[j];
            if in_a(x) {
                *slot = self.position[x as usize];
            } else if across_a.is_none() {
                across_a = Some((j, x));
                *slot = na as u8;
            } else {
                return None;
            }
        }
        let mut across_b: Option<(usize, u8)> = None;
        for (slot, &j) in b.iter_mut().zip(&self.b_tracks) {
            let x = perm[j];
            if !in_a(x) {
                *slot = self.position[x as usize];
            } else {
                // Only one A identity can be on B when only one B identity
                // is on A.
                across_b = Some((j, x));
                *slot = nb as u8;
            }
        }
        let exchanged = match (across_a, across_b) {
            (None, None) => {
                a[na] = na as u8;
                b[nb] = nb as u8;
                false
            }
            (Some((ja, y)), Some((jb, x))) => {
                // An identity crossing two links at once, or a phantom
                // crossing, is beyond one exchange: dropped.
                let chained = (self.phantom_tracks >> ja) & 1 != 0
                    || (self.phantom_tracks >> jb) & 1 != 0
                    || (self.star_identities >> x) & 1 != 0
                    || (self.star_identities >> y) & 1 != 0;
                if chained {
                    return None;
                }
                a[na] = self.position[x as usize];
                b[nb] = self.position[y as usize];
                true
            }
            _ => return None,
        };
        Some((
            self.a_table.rank(&a[..na + 1]),
            self.b_table.rank(&b[..nb + 1]),
            exchanged,
        ))
    }
}

/// The linked cut of `group` along `cut`: A gets a new port `pa` and B a
/// new port `pb` (global ids ≥ n, partners of each other), each factor a
/// projection of the group conditioned on at most one identity crossing.
/// With e the exchange flag, the joint f_A(σ_A)·f_B(σ_B)·[e_A = e_B] is
/// P(e)·P(σ_A | e)·P(σ_B | e): f_A(σ_A) = P(σ_A, e), f_B(σ_B) = P(σ_B | e).
pub(crate) fn apply_linked(
    group: &Group,
    cut: &Cut,
    ports: &[Port],
    pa: u32,
    pb: u32,
) -> Result<LinkedCut, BeliefError> {
    let projector = LinkedProjector::new(group, cut, ports)?;
    let table = group.table();
    let (mut fa, mut fb) = (Vec::new(), Vec::new());
    let mut by_flag = [0.0f64; 2];
    for (r, p) in group.entries() {
        if let Some((ra, rb, e)) = projector.project(table.get(r as usize)) {
            fa.push((ra as u32, p));
            fb.push((rb as u32, p));
            by_flag[usize::from(e)] += p;
        }
    }
    let (mut fa, mut fb) = (accumulate(fa), accumulate(fb));
    let mass = by_flag[0] + by_flag[1];
    if !(mass.is_finite() && mass > 0.0) {
        return Err(BeliefError::Degenerate { normalizer: mass });
    }
    fa.iter_mut().for_each(|e| e.1 /= mass);
    let (nb, b_table) = (projector.b_tracks.len(), projector.b_table);
    for (r, p) in fb.iter_mut() {
        let e = usize::from(b_table.get(*r as usize)[nb] as usize != nb);
        if *p != 0.0 {
            *p /= by_flag[e];
        }
    }
    let mut info = 0.0;
    for (r, p) in group.entries() {
        if let Some((ra, rb, _)) = projector.project(table.get(r as usize)) {
            let joint = p / mass;
            info += joint * (joint / (lookup(&fa, ra as u32) * lookup(&fb, rb as u32))).ln();
        }
    }
    // f_B = P(σ_B | e) sums to one per flag: scaled to sum to one (a
    // factor's scale does not change the joint).
    let total: f64 = fb.iter().map(|e| e.1).sum();
    fb.iter_mut().for_each(|e| e.1 /= total);
    let (a_count, b_count) = (projector.a_table.count(), b_table.count());
    let side = |tracks: &[usize], inside: bool, port: u32, probs: Vec<(u32, f64)>| {
        let mut t: Vec<u32> = tracks.iter().map(|&j| group.tracks[j]).collect();
        t.push(port);
        let mut ids: Vec<u32> = (0..group.size())
            .filter(|&x| (cut.identities & (1 << x) != 0) == inside)
            .map(|x| group.identities[x])
            .collect();
        ids.push(port);
        let count = if inside { a_count } else { b_count };
        Group {
            tracks: t,
            identities: ids,
            probs: Assignments::from_sorted(count, probs),
        }
    };
    Ok(LinkedCut {
        a: side(&projector.a_tracks, true, pa, fa),
        b: side(&projector.b_tracks, false, pb, fb),
        mass,
        mutual_information: info.max(0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_certain_track_is_cut_off_for_free() {
        // Tracks 0, 1 mixed (swap 0.3); track 2 joined them but never mixed.
        let mut g = Group::uniform(vec![0, 1], vec![5, 6]).unwrap();
        g.read(0, 0, 0.9, 0.1).unwrap();
        g.mix(0, 1, 0.3);
        let g = g.join(&Group::certain(2, 7)).unwrap();
        let cuts = best_cuts(&g, 2, 0, &[]);
        let one = cuts[1].unwrap();
        assert_eq!((one.tracks, one.identities), (0b100, 0b100));
        assert!(one.cost() < 1e-12, "{one:?}");
        let (a, b) = apply(&g, &one).unwrap();
        assert_eq!((a.tracks(), a.identities()), (&[2][..], &[7][..]));
        assert_eq!((b.tracks(), b.identities()), (&[0, 1][..], &[5, 6][..]));
        let m = b.local_marginals();
        let want = 0.9 * 0.7 + 0.1 * 0.3;
        assert!((m[0][0] - want).abs() < 1e-12);
    }

    #[test]
    fn an_uncertain_cut_costs_its_lost_mass() {
        // Two tracks swapped with probability ¼: cutting them apart keeps
        // the more likely pairing and loses ¼ of the mass.
        let mut g = Group::certain(0, 0).join(&Group::certain(1, 1)).unwrap();
        g.mix(0, 1, 0.25);
        let cut = best_cuts(&g, 0, 0, &[])[1].unwrap();
        assert_eq!(cut.identities, 0b01);
        assert!((cut.mass - 0.75).abs() < 1e-12);
        assert!((cut.cost() - 0.25).abs() < 1e-12);
    }

    #[test]
    fn correlated_sides_cost_their_mutual_information() {
        // {0,1} and {2,3} each swap together or not at all: E = {π(A) =
        // I_A} is sure, but the sides share one bit (ln 2 nats).
        let table = permutations(4).unwrap();
        let both = table.rank(&[1, 0, 3, 2]) as u32;
        let none = table.rank(&[0, 1, 2, 3]) as u32;
        let g = Group::from_parts(
            vec![0, 1, 2, 3],
            vec![0, 1, 2, 3],
            vec![(none, 0.5), (both, 0.5)],
        )
        .unwrap();
        let cut = best_cuts(&g, 0, 0, &[])[2].unwrap();
        assert_eq!((cut.tracks, cut.identities), (0b0011, 0b0011));
        assert!((cut.mass - 1.0).abs() < 1e-12);
        assert!((cut.mutual_information - 2f64.ln()).abs() < 1e-12);
    }
}
