//! Where the factored identity belief starts on a stream whose leaders
//! hold it (`Begin::factored_identity`): what the leaders and the
//! coordinator must agree on about it (its trees on the wire: `wire`).

use crate::PlacementError;
use idmesh_identity::factored::IdentityShare;
use idmesh_identity::FactoredIdentityOptions;
use idmesh_protocol::wire::sensor_to_leader::Begin;

/// The options of the factored identity belief a `Begin` names.
pub fn identity_options(cap: u32) -> FactoredIdentityOptions {
    FactoredIdentityOptions {
        max_group: cap as usize,
        ..FactoredIdentityOptions::default()
    }
}

/// Leader `me`'s part of the factored identity belief at the start (None
/// where the leaders keep rows of the information matrix instead): every
/// track alone with its known identity, held by the leader surveilling
/// it or, unheld, by its keeper.
pub fn start_identity(begin: &Begin, me: u16) -> Result<Option<IdentityShare>, PlacementError> {
    let (Some(cap), Some(initial)) = (begin.factored_identity, &begin.initial_identity) else {
        return Ok(None);
    };
    let share = IdentityShare::start(initial, identity_options(cap), |t| {
        begin.holds_at_start(t, me)
    })?;
    Ok(Some(share))
}
