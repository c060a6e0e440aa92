//! The identity event a trace line carries ([`identity_event_of`]): where
//! the protocol's lines become identity events, as
//! `idmesh_belief::from_trace` is for the property events, so `idmesh
//! replay`, the evaluation and the leaders apply the same events.

use crate::event::{Identify, IdentityEvent};
use idmesh_belief::mix_of;
use idmesh_protocol::trace::Line;

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

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_belief::event_of;
    use idmesh_belief::{Event, Mix, Observe};
    use idmesh_protocol::trace;

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
