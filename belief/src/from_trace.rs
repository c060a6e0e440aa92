//! The engine's reading of a stream, in the protocol's terms: the field a
//! trace header or a stream's `Begin` describes ([`field_of`]), and the
//! event a trace line carries for a property filter ([`event_of`]) or an
//! identity filter ([`identity_event_of`]). The one place where trace lines
//! become engine events, so `idmesh replay`, the evaluation and the leaders
//! start from the same belief and apply the same events.

use crate::event::{Event, Field, Mix, Observe};
use crate::identity::{Identify, IdentityEvent};
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

/// The identity event a line carries: `mix` and `identify`; `None` for the
/// lines that mean nothing to an identity belief (`observe`, `move`) and
/// for those that are not events.
pub fn identity_event_of(line: &Line) -> Option<IdentityEvent> {
    match line {
        Line::Mix(mix) => Some(IdentityEvent::Mix(mix_of(mix))),
        Line::Identify(read) => Some(IdentityEvent::Identify(Identify {
            track: read.track,
            identity: read.identity,
            accuracy: read.accuracy,
        })),
        Line::Observe(_) | Line::Move(_) | Line::Header(_) | Line::Truth(_) | Line::Detect(_) => {
            None
        }
    }
}

fn mix_of(mix: &idmesh_protocol::trace::Mix) -> Mix {
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
    use idmesh_protocol::trace::{self, Header};
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

    #[test]
    fn each_filter_takes_the_lines_that_bear_on_it() {
        let mix = Line::Mix(trace::Mix {
            time: 1.0,
            a: 0,
            b: 2,
            swap: 0.25,
        });
        let observe = Line::Observe(trace::Observe {
            time: 1.0,
            track: 1,
            red: 0.8,
            blue: 0.2,
            sensor: None,
        });
        let identify = Line::Identify(trace::Identify {
            time: 1.0,
            track: 2,
            identity: 0,
            accuracy: 0.9,
        });
        let moved = Line::Move(trace::Move {
            time: 1.0,
            track: 0,
            x: 0.0,
            y: 0.0,
        });
        let want_mix = Mix {
            a: 0,
            b: 2,
            swap: 0.25,
        };
        assert_eq!(event_of(&mix), Some(Event::Mix(want_mix)));
        assert_eq!(identity_event_of(&mix), Some(IdentityEvent::Mix(want_mix)));
        assert_eq!(
            event_of(&observe),
            Some(Event::Observe(Observe {
                track: 1,
                red: 0.8,
                blue: 0.2
            }))
        );
        assert_eq!(identity_event_of(&observe), None);
        assert_eq!(event_of(&identify), None);
        assert_eq!(
            identity_event_of(&identify),
            Some(IdentityEvent::Identify(Identify {
                track: 2,
                identity: 0,
                accuracy: 0.9
            }))
        );
        assert_eq!((event_of(&moved), identity_event_of(&moved)), (None, None));
    }
}
