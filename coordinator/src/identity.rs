//! What an identity query asks for: the method its marginals are computed
//! by (`?marginals=auto|exact|metropolis|sinkhorn|bethe`; exact by default
//! up to [`EXACT_BY_DEFAULT`] tracks, `auto` beyond: every independent
//! block of mixed tracks exactly when small, half-Bethe when larger,
//! sampled when larger still — `idmesh_identity::marginals`). The driver
//! answers it (`driver::identity`).

use crate::driver::gather::GatherError;
use idmesh_identity::MarginalMethod;
use idmesh_identity::DEFAULT_SAMPLES;

/// The most tracks for which a query that names no method gets exact
/// marginals (the permanent of an N × N matrix: 2^16 Gray-code steps of
/// N² each, milliseconds; at 22 it is seconds).
pub(crate) const EXACT_BY_DEFAULT: usize = 16;

/// The `marginals` an answer of the factored identity belief names: its
/// marginals are the belief's own, exact per group.
pub(crate) const FACTORED: &str = "factored-identity";

/// How a query wants its marginals computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Exact up to [`EXACT_BY_DEFAULT`] tracks, `auto` beyond.
    BySize,
    Named(MarginalMethod),
}

impl Method {
    /// `marginals=<name>` (and `samples=`, `seed=` for metropolis) from a
    /// query's parameters.
    pub(crate) fn from_parameters(
        marginals: Option<&str>,
        samples: Option<&str>,
        seed: Option<&str>,
    ) -> Result<Method, String> {
        let Some(name) = marginals else {
            return Ok(Method::BySize);
        };
        let samples = match samples {
            None => DEFAULT_SAMPLES,
            Some(s) => s
                .parse()
                .ok()
                .filter(|&s: &usize| s > 0)
                .ok_or_else(|| format!("samples={s}: expected a positive count"))?,
        };
        let seed = match seed {
            None => 0,
            Some(s) => s
                .parse()
                .map_err(|_| format!("seed={s}: expected an unsigned integer"))?,
        };
        MarginalMethod::named(name, samples, seed)
            .map(Method::Named)
            .ok_or_else(|| {
                format!("marginals={name}: expected auto, exact, metropolis, sinkhorn or bethe")
            })
    }

    /// The method for a cut of `n` tracks.
    pub(crate) fn for_tracks(self, n: usize) -> Result<MarginalMethod, GatherError> {
        match self {
            Method::BySize if n <= EXACT_BY_DEFAULT => Ok(MarginalMethod::Exact),
            // Exact on each small block of mixed tracks, half-Bethe or
            // Metropolis on large ones: answers at any size
            // (idmesh_identity::marginals).
            Method::BySize => Ok(MarginalMethod::Auto),
            // Exact takes any n whose blocks are small enough; the engine
            // names the block that is not.
            Method::Named(method) => Ok(method),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_query_names_its_method_or_gets_one_by_size() {
        let by_size = Method::from_parameters(None, None, None).unwrap();
        assert_eq!(by_size.for_tracks(12).unwrap(), MarginalMethod::Exact);
        assert_eq!(by_size.for_tracks(40).unwrap(), MarginalMethod::Auto);
        let sampled = Method::from_parameters(Some("metropolis"), Some("500"), Some("7")).unwrap();
        assert_eq!(
            sampled.for_tracks(40).unwrap(),
            MarginalMethod::Metropolis {
                samples: 500,
                burn_in: 50,
                seed: 7
            }
        );
        // Exact is passed on at any size: the engine answers when every
        // block of mixed tracks is small and names the block when not.
        let exact = Method::from_parameters(Some("exact"), None, None).unwrap();
        assert_eq!(exact.for_tracks(1000).unwrap(), MarginalMethod::Exact);
        assert!(Method::from_parameters(Some("guess"), None, None).is_err());
        assert!(Method::from_parameters(Some("metropolis"), Some("0"), None).is_err());
        assert!(Method::from_parameters(Some("metropolis"), None, Some("-1")).is_err());
    }
}
