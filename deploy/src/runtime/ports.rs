//! Loopback ports for a topology written before its processes start: the
//! bench's deployments and the process tests' (`idmesh-tests`) pick them
//! here, and nowhere else.
//!
//! A topology names its ports before its processes bind them, so a port
//! must stay free in between; [`pick_free_ports`] makes that likely:
//!
//! - **Below the kernel's ephemeral range.** Every outgoing connection,
//!   and every QUIC client's socket, takes an ephemeral port from the
//!   kernel: a port the kernel once handed us (`bind(0)`) can be handed to
//!   such a socket before our process binds it. That happened in CI: a
//!   secured leader's QUIC listener found its UDP port taken and the
//!   deployment never answered. Ports below the ephemeral range are never
//!   given out that way.
//! - **Free for TCP and for UDP.** A secured topology listens on QUIC
//!   (UDP) at the port its `tcp/` endpoint names.
//! - **Never twice in one process**, and **all of one call bound at once**
//!   until the call returns: two processes of one topology on the same
//!   port make it invalid.
//! - **From where the process id points**, so that test binaries run one
//!   after the other do not walk the same ports (sockets of the last one
//!   may linger).

use anyhow::{bail, Result};
use std::net::{TcpListener, UdpSocket};
use std::sync::Mutex;

/// Every port this process has handed out.
static GIVEN: Mutex<Vec<u16>> = Mutex::new(Vec::new());

/// `n` distinct loopback ports, each free now for TCP and for UDP, none
/// handed out before by this process, all below the kernel's ephemeral
/// range ([`non_ephemeral_ports`]). Each stays bound until all `n` are
/// found, then all are released for the processes that will listen there.
pub fn pick_free_ports(n: usize) -> Result<Vec<u16>> {
    pick_in(n, non_ephemeral_ports(), std::process::id())
}

/// [`pick_free_ports`] in `low..high`, starting where `seed` points.
fn pick_in(n: usize, (low, high): (u16, u16), seed: u32) -> Result<Vec<u16>> {
    let mut given = GIVEN.lock().unwrap_or_else(|e| e.into_inner());
    let span = u32::from(high - low);
    let start = seed.wrapping_mul(7919) % span;
    let mut held: Vec<(TcpListener, UdpSocket)> = Vec::with_capacity(n);
    let mut ports = Vec::with_capacity(n);
    for step in 0..span {
        if ports.len() == n {
            break;
        }
        let port = low + ((start + step) % span) as u16;
        if given.contains(&port) {
            continue;
        }
        let (Ok(tcp), Ok(udp)) = (
            TcpListener::bind(("127.0.0.1", port)),
            UdpSocket::bind(("127.0.0.1", port)),
        ) else {
            continue;
        };
        held.push((tcp, udp));
        ports.push(port);
    }
    if ports.len() < n {
        bail!(
            "only {} of {n} loopback ports in {low}..{high} are free for TCP and UDP",
            ports.len()
        );
    }
    given.extend(&ports);
    Ok(ports)
}

/// The ports from 10,000 up to the kernel's ephemeral range
/// (`ip_local_port_range`, 32768 by default): nothing is given them
/// unasked. Above it if the range starts too low to leave room.
pub(crate) fn non_ephemeral_ports() -> (u16, u16) {
    let range = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range").ok();
    outside_of(range.as_deref())
}

/// [`non_ephemeral_ports`] given the text of `ip_local_port_range`.
fn outside_of(range: Option<&str>) -> (u16, u16) {
    let bounds: Vec<u16> = range
        .iter()
        .flat_map(|r| r.split_whitespace())
        .filter_map(|n| n.parse().ok())
        .collect();
    match bounds[..] {
        [first, _] if first >= 12_000 => (10_000, first),
        [_, last] if last <= 63_000 => (last + 1, u16::MAX),
        _ => (10_000, 32_768),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_call_gives_distinct_free_ports_outside_the_ephemeral_range() {
        let (low, high) = non_ephemeral_ports();
        let ports = pick_free_ports(12).unwrap();
        assert_eq!(ports.len(), 12);
        let mut sorted = ports.clone();
        sorted.sort_unstable();
        sorted.dedup();
        assert_eq!(sorted.len(), 12, "{ports:?}");
        for &port in &ports {
            assert!((low..high).contains(&port), "{port} outside {low}..{high}");
            // Released: the process the topology names can bind it.
            TcpListener::bind(("127.0.0.1", port)).unwrap();
            UdpSocket::bind(("127.0.0.1", port)).unwrap();
        }
        let more = pick_free_ports(12).unwrap();
        assert!(more.iter().all(|p| !ports.contains(p)), "handed out twice");
    }

    #[test]
    fn a_port_in_use_is_passed_over() {
        // Two calls from the same seed: the first port of the second would
        // be the first's, had it not been handed out; a port some other
        // socket holds is passed over too.
        let range = non_ephemeral_ports();
        let seed = 4242;
        let first = pick_in(1, range, seed).unwrap()[0];
        let busy = TcpListener::bind(("127.0.0.1", first + 1)).ok();
        let second = pick_in(2, range, seed).unwrap();
        assert!(!second.contains(&first), "{second:?} again {first}");
        if busy.is_some() {
            assert!(!second.contains(&(first + 1)), "{second:?} is in use");
        }
    }

    #[test]
    fn the_range_stays_below_the_kernels_ephemeral_ports() {
        assert_eq!(outside_of(Some("32768\t60999\n")), (10_000, 32_768));
        assert_eq!(outside_of(Some("15000 60999")), (10_000, 15_000));
        // Too low to leave room below: above it.
        assert_eq!(outside_of(Some("1024 40000")), (40_001, u16::MAX));
        assert_eq!(outside_of(None), (10_000, 32_768));
    }

    #[test]
    fn too_many_ports_is_an_error_that_says_so() {
        let e = pick_in(50, (20_000, 20_010), 1).unwrap_err();
        assert!(format!("{e}").contains("of 50 loopback ports"), "{e}");
    }
}
