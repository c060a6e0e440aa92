//! The centralized twin of a deployment: `idmesh replay --topology FILE`
//! sets replay's options from the topology so that it computes what the
//! deployment computes, to 1e-9 (docs/guide/replay.md, "A deployment's
//! twin").

use super::topology::{BeliefKind, RegionsSetting, Sparsification, SplitSetting, Topology};
use anyhow::{bail, Result};
use idmesh_eval::replay::args::{CouplingChoice, Places, SplitChoice};
use idmesh_eval::replay::{Method, ReplayArgs};

impl Topology {
    /// Sets `args` to the replay that equals this deployment. Refuses
    /// options that the topology decides, given as well, and a deployment
    /// that no centralized engine equals (Radon leaders each thresholding
    /// their own sets).
    pub fn replay_twin(&self, args: &mut ReplayArgs) -> Result<()> {
        let given = [
            (args.method.is_some(), "--method"),
            (args.coupling != CouplingChoice::Local, "--coupling"),
            (args.max_component.is_some(), "--max-component"),
            (args.split != SplitChoice::Original, "--split"),
            (args.regions.is_some(), "--regions"),
            (args.leaders.is_some(), "--leaders"),
            (args.budget.is_some(), "--budget"),
            (args.distributed_rule, "--distributed-rule"),
        ];
        if let Some((_, option)) = given.iter().find(|(set, _)| *set) {
            bail!("--topology sets the belief's options itself: give it without {option}");
        }
        match self.belief {
            BeliefKind::Factored => {
                args.method = Some(Method::Factored);
                args.max_component = Some(self.max_component as usize);
                args.split = match self.split {
                    SplitSetting::Original => SplitChoice::Original,
                    SplitSetting::Recent => SplitChoice::Recent,
                    SplitSetting::LeastLoss => SplitChoice::LeastLoss,
                };
                if self.regional && self.leader.len() > 1 {
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
