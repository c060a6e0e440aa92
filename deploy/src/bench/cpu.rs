//! Every process's CPU time, from the operating system (`/proc/<pid>/stat`,
//! read with the procfs crate). On this 2-core machine all the processes of
//! a deployment share two cores, so the wall clock cannot show what more
//! leaders buy; each process's CPU seconds can: with a host per process,
//! the busiest process bounds the throughput.

use anyhow::{Context, Result};
use std::collections::BTreeMap;

/// The CPU seconds (user + system) each process had used at one moment.
#[derive(Debug, Clone, Default)]
pub struct CpuTimes(BTreeMap<String, f64>);

impl CpuTimes {
    /// Reads the CPU time of every `(name, pid)`.
    pub fn read<'a>(processes: impl IntoIterator<Item = (&'a str, u32)>) -> Result<CpuTimes> {
        let ticks = procfs::ticks_per_second() as f64;
        let mut times = BTreeMap::new();
        for (name, pid) in processes {
            let stat = procfs::process::Process::new(pid as i32)
                .and_then(|p| p.stat())
                .with_context(|| format!("the CPU time of {name} (pid {pid})"))?;
            times.insert(name.to_string(), (stat.utime + stat.stime) as f64 / ticks);
        }
        Ok(CpuTimes(times))
    }

    /// The CPU seconds each process used since `earlier`, by name.
    pub fn since(&self, earlier: &CpuTimes) -> BTreeMap<String, f64> {
        self.0
            .iter()
            .map(|(name, &now)| {
                let before = earlier.0.get(name).copied().unwrap_or(0.0);
                (name.clone(), now - before)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_busy_process_is_seen_using_cpu_and_a_gone_one_is_named() {
        let me = std::process::id();
        let before = CpuTimes::read([("bench", me)]).unwrap();
        let started = std::time::Instant::now();
        let mut x = 0u64;
        while started.elapsed() < std::time::Duration::from_millis(300) {
            x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(7));
        }
        let used = CpuTimes::read([("bench", me)]).unwrap().since(&before);
        assert!(used["bench"] > 0.05, "{used:?}");
        let gone = CpuTimes::read([("ghost", u32::MAX / 2)]).unwrap_err();
        assert!(format!("{gone:#}").contains("ghost"), "{gone:#}");
    }
}
