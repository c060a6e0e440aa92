//! The registry of methods `eval` can run, each named as on its command line
//! and in its tables: `exact`, `order1`…`order3`, `threshold:B`,
//! `overcomplete:B`, `distributed:B` (overcomplete with the distributed
//! conditioning rule of Section 5.4), `particles:P`, and `factored` (the
//! factored belief of `idmesh_belief::factored`, default options; see
//! [`FACTORED_AVAILABLE`]), `factored-local`, and `deployed:L` (what a
//! deployment of L leaders computes at the default settings).

use crate::filters::Recipe;
use anyhow::{bail, Context, Result};
use idmesh_belief::MAX_STATES;
use idmesh_belief::{BeliefError, Coupling, Field, PropertyFilter, Sparsify};
use idmesh_placement::split_coupling;
use std::fmt;

/// The largest n at which the exact filter runs in the grid (C(20, 10) =
/// 184,756 states): "where n ≤ 20 the exact filter is in every table".
pub(crate) const EXACT_UP_TO: usize = 20;

/// Whether `factored` (`idmesh_belief::FactoredBelief` with its default
/// options) joins the grids (see `plan.rs`). Set it to `false` to run the
/// grids without it; the name still parses.
pub(crate) const FACTORED_AVAILABLE: bool = true;

/// One method of the evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Method {
    /// The dense filter over every red set: the optimum.
    Exact,
    /// Low-order Radon projection of this order, repaired by shrinking to
    /// uniform when it leaves the simplex.
    Order(usize),
    /// Radon belief pruned to B coefficients by thresholding.
    Threshold(usize),
    /// Radon belief, OMP then thresholding at B coefficients.
    Overcomplete(usize),
    /// As `Overcomplete`, conditioning with the distributed rule.
    Distributed(usize),
    /// Particle filter with P particles.
    Particles(usize),
    /// The factored belief: exact tables over groups of tracks.
    Factored,
    /// The factored belief with [`Coupling::Local`] splits: what each of
    /// several leaders can run, measured beside the coupled default.
    FactoredLocal,
    /// What a deployment of this many leaders computes at the default
    /// settings: with one, or on a crowd small enough to be held whole,
    /// the factored belief (coupled splits); with several sharing a larger
    /// crowd, the factored belief with the local rule under the regional
    /// rule, regions fitted to the crowd from the trace's `move` lines
    /// (`idmesh_placement::Regional`; `idmesh replay --leaders L`).
    Deployed(usize),
}

impl Method {
    /// Parses a registry name: `exact`, `order1`, `threshold:100`, ….
    pub fn parse(text: &str) -> Result<Method> {
        let (head, arg) = match text.split_once(':') {
            Some((h, a)) => (h, Some(a)),
            None => (text, None),
        };
        let number = |what: &str| -> Result<usize> {
            let arg = arg.with_context(|| format!("`{head}` needs :{what}, e.g. `{head}:100`"))?;
            let value: usize = arg
                .parse()
                .with_context(|| format!("`{text}`: {what} `{arg}` is not a whole number"))?;
            if value == 0 {
                bail!("`{text}`: {what} must be at least 1");
            }
            Ok(value)
        };
        let plain = |method: Method| -> Result<Method> {
            if arg.is_some() {
                bail!("`{head}` takes no argument, got `{text}`");
            }
            Ok(method)
        };
        match head {
            "exact" => plain(Method::Exact),
            "order1" => plain(Method::Order(1)),
            "order2" => plain(Method::Order(2)),
            "order3" => plain(Method::Order(3)),
            "factored" => plain(Method::Factored),
            "factored-local" => plain(Method::FactoredLocal),
            "threshold" => Ok(Method::Threshold(number("budget")?)),
            "overcomplete" => Ok(Method::Overcomplete(number("budget")?)),
            "distributed" => Ok(Method::Distributed(number("budget")?)),
            "particles" => Ok(Method::Particles(number("particles")?)),
            "deployed" => Ok(Method::Deployed(number("leaders")?)),
            _ => bail!(
                "unknown method `{text}`: expected exact, order1, order2, order3, threshold:B, \
                 overcomplete:B, distributed:B, particles:P, factored, factored-local or \
                 deployed:L"
            ),
        }
    }

    /// A readable label for tables: `overcomplete (B = 500)`.
    pub(crate) fn label(&self) -> String {
        match self {
            Method::Exact => "exact".into(),
            Method::Order(j) => format!("order {j}"),
            Method::Threshold(b) => format!("threshold (B = {b})"),
            Method::Overcomplete(b) => format!("overcomplete (B = {b})"),
            Method::Distributed(b) => format!("overcomplete, distributed rule (B = {b})"),
            Method::Particles(p) => format!("particles (P = {p})"),
            Method::Factored => "factored".into(),
            Method::FactoredLocal => "factored, local rule".into(),
            Method::Deployed(l) => format!("factored, as deployed on {l} leaders"),
        }
    }

    /// Whether the method runs at n tracks with k red: the exact filter up
    /// to [`EXACT_UP_TO`] tracks, the low-order ones while their tables fit,
    /// the factored one only once it exists.
    pub(crate) fn fits(&self, n: usize, k: usize) -> bool {
        let choose = |n: usize, r: usize| -> f64 {
            (0..r).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
        };
        match *self {
            Method::Exact => n <= EXACT_UP_TO && choose(n, k.min(n)) <= MAX_STATES as f64,
            Method::Order(j) => {
                let j = j.min(k).min(n);
                (0..=j).map(|u| choose(n, u)).sum::<f64>() <= MAX_STATES as f64
            }
            Method::Factored | Method::FactoredLocal | Method::Deployed(_) => FACTORED_AVAILABLE,
            _ => true,
        }
    }

    /// The filter this method names (`seed` drives the randomized ones),
    /// for the one factory ([`Recipe`]).
    pub(crate) fn recipe(&self, seed: u64) -> Recipe {
        let radon = |sparsify: Sparsify, distributed_rule: bool| Recipe::Radon {
            sparsify: Some(sparsify),
            distributed_rule,
        };
        match *self {
            Method::Exact => Recipe::Exact,
            Method::Order(j) => Recipe::Order(j),
            Method::Threshold(b) => radon(Sparsify::threshold(b), false),
            Method::Overcomplete(b) => radon(Sparsify::overcomplete(b), false),
            Method::Distributed(b) => radon(Sparsify::overcomplete(b), true),
            Method::Particles(count) => Recipe::Particles { count, seed },
            Method::Factored => Recipe::factored(Coupling::Coupled),
            Method::FactoredLocal => Recipe::factored(Coupling::Local),
            // Its regions wrap the belief where the trace is replayed
            // (`Method::leaders`), on a crowd it spreads; a crowd held
            // whole is one holder's ([`Running::new`](super::score)).
            Method::Deployed(leaders) => Recipe::factored(split_coupling(leaders <= 1)),
        }
    }

    /// The leaders a deployed method shares the tracks among: its replay
    /// runs the regional rule with fitted regions over the trace's `move`
    /// lines.
    pub(crate) fn leaders(&self) -> Option<usize> {
        match *self {
            Method::Deployed(leaders) => Some(leaders),
            _ => None,
        }
    }

    /// Builds the filter for `field`; `seed` drives the randomized ones.
    pub(crate) fn build(
        &self,
        field: Field,
        seed: u64,
    ) -> Result<Box<dyn PropertyFilter>, BeliefError> {
        self.recipe(seed).build(field)
    }
}

/// The registry name, which [`Method::parse`] reads back.
impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Method::Exact => write!(f, "exact"),
            Method::Order(j) => write!(f, "order{j}"),
            Method::Threshold(b) => write!(f, "threshold:{b}"),
            Method::Overcomplete(b) => write!(f, "overcomplete:{b}"),
            Method::Distributed(b) => write!(f, "distributed:{b}"),
            Method::Particles(p) => write!(f, "particles:{p}"),
            Method::Factored => write!(f, "factored"),
            Method::FactoredLocal => write!(f, "factored-local"),
            Method::Deployed(l) => write!(f, "deployed:{l}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_belief::{Event, Mix};

    #[test]
    fn names_round_trip() {
        for name in [
            "exact",
            "order1",
            "order3",
            "threshold:100",
            "overcomplete:500",
            "distributed:60",
            "particles:1000",
            "factored",
            "factored-local",
            "deployed:8",
        ] {
            assert_eq!(Method::parse(name).unwrap().to_string(), name);
        }
        for bad in [
            "order4",
            "overcomplete",
            "particles:0",
            "exact:3",
            "radon",
            "deployed",
        ] {
            assert!(Method::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn every_method_builds_and_runs() {
        let field = Field::known(10, vec![0, 1, 2, 3, 4]);
        for name in [
            "exact",
            "order1",
            "order3",
            "threshold:20",
            "overcomplete:50",
            "distributed:50",
            "particles:100",
            "factored",
            "factored-local",
        ] {
            let mut filter = Method::parse(name)
                .unwrap()
                .build(field.clone(), 1)
                .unwrap();
            filter
                .apply(&Event::Mix(Mix {
                    a: 0,
                    b: 9,
                    swap: 0.5,
                }))
                .unwrap();
            let total: f64 = filter.marginals().unwrap().iter().sum();
            assert!((total - 5.0).abs() < 1e-6, "{name}: {total}");
        }
        assert_eq!(Method::Factored.fits(10, 5), FACTORED_AVAILABLE);
        assert!(Method::Exact.fits(20, 10) && !Method::Exact.fits(21, 10));
        assert!(Method::Order(3).fits(100, 50));
    }
}
