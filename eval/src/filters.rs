//! The one factory of property filters: what `idmesh replay --method M`
//! and the evaluation's registry names (`eval::methods`) both turn into a
//! running filter. Each side maps its own names to a [`Recipe`]; only
//! [`Recipe::build`] knows how each filter is put together (the repair of
//! the low-order projections, the Radon options, the factored coupling).

use idmesh_belief::{
    BeliefError, Coupling, FactoredBelief, FactoredOptions, Field, ParticleFilter, PropertyFilter,
    RadonBelief, RadonOptions, Sparsify,
};
use idmesh_belief::{DenseFilter, LowOrderFilter, LowOrderRepair};

/// A property filter and its settings, before it meets a field.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Recipe {
    /// The dense filter over every red set: the optimum.
    Exact,
    /// The low-order Radon projection of this order, shrunk towards uniform
    /// whenever it leaves the simplex.
    Order(usize),
    /// The Radon belief: exact without `sparsify`; conditioning exactly or
    /// with the distributed rule of Section 5.4.
    Radon {
        sparsify: Option<Sparsify>,
        distributed_rule: bool,
    },
    /// Sequential Monte Carlo with `count` particles.
    Particles { count: usize, seed: u64 },
    /// The factored belief with these options (the coupling of its
    /// splits, the largest component, the split rule).
    Factored(FactoredOptions),
}

impl Recipe {
    /// The factored belief with the default options but for `coupling`.
    pub(crate) fn factored(coupling: Coupling) -> Recipe {
        Recipe::Factored(FactoredOptions {
            coupling,
            ..FactoredOptions::default()
        })
    }

    /// Builds the filter for `field`.
    pub(crate) fn build(&self, field: Field) -> Result<Box<dyn PropertyFilter>, BeliefError> {
        Ok(match self {
            Recipe::Exact => Box::new(DenseFilter::new(field)?),
            // Without the repair the paper's order-j projections leave the
            // simplex on crowd traces and an observation gets "negative
            // probability"; see `LowOrderRepair`.
            Recipe::Order(order) => Box::new(LowOrderFilter::with_repair(
                field,
                *order,
                LowOrderRepair::ShrinkToUniform,
            )?),
            Recipe::Radon {
                sparsify,
                distributed_rule,
            } => {
                let options = RadonOptions {
                    sparsify: sparsify.clone(),
                    distributed_rule: *distributed_rule,
                    ..RadonOptions::default()
                };
                Box::new(RadonBelief::with_options(field, options)?)
            }
            Recipe::Particles { count, seed } => {
                Box::new(ParticleFilter::new(field, *count, *seed)?)
            }
            Recipe::Factored(options) => {
                Box::new(FactoredBelief::with_options(field, options.clone())?)
            }
        })
    }
}
