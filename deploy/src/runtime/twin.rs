//! The centralized twin of a deployment: `idmesh replay --topology FILE`
//! sets replay's options from the topology so that it computes what the
//! deployment computes, to 1e-9 (docs/guide/replay.md, "A deployment's
//! twin"). On a trace of identities alone the twin is the identity
//! belief the leaders hold: the factored identity belief with a known
//! start on the factored belief (`identity = "factored"`), the
//! information matrix otherwise.

use super::topology::{BeliefKind, RegionsSetting, Sparsification, SplitSetting, Topology};
use anyhow::{bail, Result};
use idmesh_eval::replay::{Method, ReplayArgs};
use idmesh_eval::replay::{Places, SplitChoice};
use idmesh_placement::split_coupling;
use idmesh_protocol::trace::TraceReader;

impl Topology {
    /// Sets `args` to the replay that equals this deployment. Refuses
    /// options that the topology decides, given as well, and a deployment
    /// that no centralized engine equals (Radon leaders each thresholding
    /// their own sets).
    pub fn replay_twin(&self, args: &mut ReplayArgs) -> Result<()> {
        let given = [
            (args.method.is_some(), "--method"),
            (args.coupling.is_some(), "--coupling"),
            (args.max_component.is_some(), "--max-component"),
            (args.split != SplitChoice::LeastLoss, "--split"),
            (args.regions.is_some(), "--regions"),
            (args.leaders.is_some(), "--leaders"),
            (args.spread_above.is_some(), "--spread-above"),
            (args.budget.is_some(), "--budget"),
            (args.distributed_rule, "--distributed-rule"),
        ];
        if let Some((_, option)) = given.iter().find(|(set, _)| *set) {
            bail!("--topology sets the belief's options itself: give it without {option}");
        }
        // A trace of identities alone: the identity belief its leaders
        // hold (an unreadable header is left to replay, which names it).
        let header = TraceReader::open(&args.trace)
            .ok()
            .and_then(|mut r| r.read_header().ok());
        let tracks = header.as_ref().map(|h| h.tracks);
        if let Some(header) = header {
            if header.identities.is_some() && header.red_count().is_none() {
                let trees = self.belief == BeliefKind::Factored
                    && header.initial_identity.is_some()
                    && self.factored_identity().is_some();
                args.method = Some(match trees {
                    true => Method::FactoredIdentity,
                    false => Method::InformationMatrix,
                });
                return Ok(());
            }
        }
        match self.belief {
            BeliefKind::Factored => {
                args.method = Some(Method::Factored);
                args.max_component = Some(self.max_component as usize);
                // What the leaders weigh their splits by, whether or not
                // regions share the belief among them: a crowd held whole
                // by the first leader (an unreadable header is left to
                // replay, which names it) is one holder's.
                let whole = self
                    .factored()
                    .is_some_and(|f| tracks.is_some_and(|n| f.whole(n as u32, self.leader.len())));
                args.coupling = Some(split_coupling(whole).into());
                args.spread_above = Some(self.spread_above);
                args.split = match self.split {
                    SplitSetting::Original => SplitChoice::Original,
                    SplitSetting::Recent => SplitChoice::Recent,
                    SplitSetting::LeastLoss => SplitChoice::LeastLoss,
                };
                if self.regional && !whole {
                    match self.regions {
                        RegionsSetting::Fitted => args.leaders = Some(self.leader.len() as u16),
                        RegionsSetting::Fixed => {
                            args.regions = Some(Places(
                                self.leader
                                    .iter()
                                    .map(|l| l.at.map_or((0.0, 0.0), |[x, y]| (x, y)))
                                    .collect(),
                            ))
                        }
                    }
                }
            }
            BeliefKind::Radon if self.budget == 0 => {
                args.method = Some(Method::Overcomplete);
                args.distributed_rule = self.distributed_rule;
            }
            BeliefKind::Radon => bail!(
                "belief = \"radon\" with budget = {}: each leader thresholds its own sets \
                 ({}), which no centralized engine computes; replay --method {} --budget N \
                 is the nearest",
                self.budget,
                match self.sparsify {
                    Sparsification::Threshold => "threshold",
                    Sparsification::Overcomplete => "OMP, then threshold",
                },
                match self.sparsify {
                    Sparsification::Threshold => "threshold",
                    Sparsification::Overcomplete => "overcomplete",
                }
            ),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::topology::IdentityKind;
    use clap::Parser;

    /// `idmesh replay`'s arguments alone.
    #[derive(Parser)]
    struct Replay {
        #[command(flatten)]
        args: ReplayArgs,
    }

    /// The twin of a trace of identities alone is the identity belief the
    /// leaders hold: trees with a known start on the factored belief at
    /// the defaults, rows without a known start or when the topology asks
    /// for the information matrix.
    #[test]
    fn an_identity_trace_gets_the_identity_belief_its_leaders_hold() {
        let temporary = tempfile::tempdir().unwrap();
        let dir = temporary.path();
        let trace = |name: &str, start: &str| {
            let path = dir.join(name);
            let header = format!(
                r#"{{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"identities":2{start}}}"#
            );
            std::fs::write(&path, header + "\n").unwrap();
            path
        };
        let known = trace("known.jsonl", r#","initial_identity":[1,0]"#);
        let unknown = trace("unknown.jsonl", "");
        let twin = |topology: &Topology, path: &std::path::Path| {
            let mut args = Replay::try_parse_from(["replay", "--trace", path.to_str().unwrap()])
                .unwrap()
                .args;
            topology.replay_twin(&mut args).unwrap();
            args.method
        };
        let mut topology = Topology::loopback(&known, 2, 1, &[7000, 7001, 7002, 7003]);
        assert_eq!(twin(&topology, &known), Some(Method::FactoredIdentity));
        assert_eq!(twin(&topology, &unknown), Some(Method::InformationMatrix));
        topology.identity = IdentityKind::InformationMatrix;
        assert_eq!(twin(&topology, &known), Some(Method::InformationMatrix));
    }
}
