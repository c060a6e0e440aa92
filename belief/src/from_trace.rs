//! The engine's reading of a stream, in the protocol's terms: the field a
//! trace header or a stream's `Begin` describes ([`field_of`]), and the
//! event a trace line carries for a property filter ([`event_of`]; an
//! identity filter's is `idmesh_identity::identity_event_of`, over the
//! same [`mix_of`]). The one place where trace lines become engine events,
//! so `idmesh replay`, the evaluation and the leaders start from the same
//! belief and apply the same events.

use crate::event::{Event, Field, Mix, Observe};
use idmesh_protocol::trace::Line;
use idmesh_protocol::StreamStart;

/// The field a stream starts from: k known (the header's `red`, or the
/// length of `initial_red`; the `Begin`'s `red`) or unknown with the
/// uniform prior over counts, and the red tracks at time 0 when given.
pub fn field_of(start: &impl StreamStart) -> Field {
    Field::with_count(
        start.tracks(),
        start.red_count(),
        start.initial_red().map(<[u32]>::to_vec),
    )
}

/// The property event a line carries: `mix` and `observe`; `None` for the
/// lines that mean nothing to a property belief (`identify`, `move`) and
/// for those that are not events.
pub fn event_of(line: &Line) -> Option<Event> {
    match line {
        Line::Mix(mix) => Some(Event::Mix(mix_of(mix))),
        Line::Observe(o) => Some(Event::Observe(Observe {
            track: o.track,
            red: o.red,
            blue: o.blue,
        })),
        // A detect line is a tracker's report, not an event: the sensor
        // stage (`idmesh extract`) turns it into mix/observe/identify
        // lines first, and the readers that feed a belief refuse it.
        Line::Identify(_) | Line::Move(_) | Line::Header(_) | Line::Truth(_) | Line::Detect(_) => {
            None
        }
    }
}

/// The engine's mix of a trace line's: the same for a property and an
/// identity belief (`idmesh_identity::identity_event_of` reads it too).
pub fn mix_of(mix: &idmesh_protocol::trace::Mix) -> Mix {
    Mix {
        a: mix.a,
        b: mix.b,
        swap: mix.swap,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::RedCount;
    use idmesh_protocol::trace::Header;
    use idmesh_protocol::wire::sensor_to_leader::Begin;

    #[test]
    fn field_from_header() {
        let mut header = Header::new(5);
        assert_eq!(field_of(&header).red, RedCount::unknown_uniform(5));
        header.initial_red = Some(vec![4, 2]);
        let field = field_of(&header);
        assert_eq!(field.red, RedCount::Known(2));
        assert_eq!(field.initial_red, Some(vec![4, 2]));
        header.initial_red = None;
        header.red = Some(3);
        assert_eq!(field_of(&header), Field::uniform(5, 3));
    }

    #[test]
    fn field_from_begin() {
        let begin = Begin {
            factored_identity: None,
            factored: None,
            tracks: 3,
            red: Some(1),
            initial_red: Some(vec![2]),
            leaders: vec!["a".into()],
            owners: vec![0; 3],
            distributed_rule: false,
            budget: 0,
            omp: false,
            identities: false,
            initial_identity: None,
        };
        assert_eq!(field_of(&begin), Field::known(3, vec![2]));
        let unknown = Begin {
            red: None,
            initial_red: None,
            ..begin
        };
        assert_eq!(field_of(&unknown).red, RedCount::unknown_uniform(3));
    }
}
