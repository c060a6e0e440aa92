//! The live runtime's tracking error beside the centralized engines', for
//! results.md. A live deployment takes minutes to score
//! (`idmesh bench --accuracy`, which writes live-accuracy.md), so the
//! evaluation does not run one: it reads the table live-accuracy.md holds
//! and sets the live factored belief, the centralized factored engine
//! (the same rule) and the live Radon runtime side by side, one row per
//! Table III point. A test keeps the committed copy equal to what the
//! committed live-accuracy.md says. [`LiveRow`] is that table's row, for
//! the bench that writes it and for this module that reads it.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

/// The file `idmesh bench --accuracy --out` writes, beside results.md.
pub(crate) const FILE: &str = "live-accuracy.md";

/// The header of live-accuracy.md's table, its rows [`LiveRow`]s.
pub const TABLE_HEADER: &str = "| n | swap | start | belief | truth lines | live tracking error | centralized tracking error | largest \\|live − centralized\\| | live seconds |\n|---:|---:|---|---|---:|---:|---:|---:|---:|";

/// One row of live-accuracy.md's table: a point and a belief, over the
/// point's seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveRow {
    pub n: usize,
    pub swap: f64,
    /// The start's label ("known start", "uniform prior").
    pub start: String,
    /// The belief's name ("factored", "factored, regional rule", "radon").
    pub belief: String,
    /// Truth lines answered, over the seeds.
    pub truth_lines: usize,
    /// Mean tracking errors over the seeds, live and centralized.
    pub live: f64,
    pub centralized: f64,
    /// The largest difference of one marginal, over every truth line and seed.
    pub largest: f64,
    /// Wall seconds of the live runs, summed over the seeds.
    pub seconds: f64,
}

impl LiveRow {
    /// The row as the table holds it.
    pub fn markdown(&self) -> String {
        format!(
            "| {} | {} | {} | {} | {} | {:.4} | {:.4} | {:.1e} | {:.1} |",
            self.n,
            self.swap,
            self.start,
            self.belief,
            self.truth_lines,
            self.live,
            self.centralized,
            self.largest,
            self.seconds,
        )
    }

    /// A line of the table read back; `None` for any other line.
    pub fn parse(line: &str) -> Option<LiveRow> {
        let cells: Vec<&str> = line
            .trim()
            .strip_prefix('|')?
            .strip_suffix('|')?
            .split('|')
            .map(str::trim)
            .collect();
        let [n, swap, start, belief, truth_lines, live, centralized, largest, seconds] =
            cells.as_slice()
        else {
            return None;
        };
        Some(LiveRow {
            n: n.parse().ok()?,
            swap: swap.parse().ok()?,
            start: start.to_string(),
            belief: belief.to_string(),
            truth_lines: truth_lines.parse().ok()?,
            live: live.parse().ok()?,
            centralized: centralized.parse().ok()?,
            largest: largest.parse().ok()?,
            seconds: seconds.parse().ok()?,
        })
    }
}

/// The section for results.md, from `dir`/live-accuracy.md; a paragraph
/// saying how to make it when the file is not there or holds no table.
pub(crate) fn section(dir: &Path) -> String {
    let mut out = String::from(
        "\n## The live runtime on the Table III crowds\n\n\
         The crowds of Table III fed to a live deployment (a coordinator, four leaders placed \
         over the crowd, a sensor, on loopback) and asked the marginals at every truth line; \
         copied from [live-accuracy.md](live-accuracy.md), where the setup is described, \
         written by `idmesh bench --accuracy --out docs/live-accuracy.md`. The live factored \
         belief is the centralized factored engine (local split rule) distributed: that \
         command fails if any marginal differs from the engine's by more than 1e-9. The live \
         Radon runtime prunes each leader's sets to its own budget (distributed rule, \
         B = 5n per leader), which no single filter reproduces. Mean tracking error over \
         the seeds:\n\n",
    );
    let path = dir.join(FILE);
    let rows = match std::fs::read_to_string(&path) {
        Ok(text) => rows_of(&text),
        Err(_) => Vec::new(),
    };
    if rows.is_empty() {
        writeln!(out, "Not measured yet: {FILE} holds no table.").unwrap();
        return out;
    }
    out.push_str(&table(&rows));
    out
}

/// The rows of live-accuracy.md's table.
fn rows_of(text: &str) -> Vec<LiveRow> {
    text.lines().filter_map(LiveRow::parse).collect()
}

/// One row per point: the live factored error and the centralized
/// engine's, the largest difference of a marginal, and the live Radon
/// runtime's error with its centralized counterpart.
fn table(rows: &[LiveRow]) -> String {
    let mut points: BTreeMap<(String, String, usize), BTreeMap<&str, &LiveRow>> = BTreeMap::new();
    for row in rows {
        points
            .entry((row.start.clone(), row.swap.to_string(), row.n))
            .or_default()
            .insert(row.belief.as_str(), row);
    }
    let mut out = String::from(
        "| start | swap | n | truth lines | live factored | centralized factored, local rule \
         | largest \\|live − centralized\\| | live factored, regional rule | live Radon \
         (distributed rule) | centralized Radon, distributed rule |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let error = |row: Option<&&LiveRow>, of: fn(&LiveRow) -> f64| {
        row.map(|r| format!("{:.4}", of(r)))
            .unwrap_or_else(|| "—".into())
    };
    for ((start, swap, n), by_belief) in &points {
        let factored = by_belief.get("factored");
        let regional = by_belief.get("factored, regional rule");
        let radon = by_belief.get("radon");
        let truth_lines = by_belief.values().map(|r| r.truth_lines).max().unwrap_or(0);
        writeln!(
            out,
            "| {start} | {swap} | {n} | {truth_lines} | {} | {} | {} | {} | {} | {} |",
            error(factored, |r| r.live),
            error(factored, |r| r.centralized),
            factored.map_or("—".into(), |r| format!("{:.1e}", r.largest)),
            error(regional, |r| r.live),
            error(radon, |r| r.live),
            error(radon, |r| r.centralized),
        )
        .unwrap();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "\
# Live accuracy\n\n\
| n | swap | start | belief | truth lines | live tracking error | centralized tracking error | largest \\|live − centralized\\| | live seconds |\n\
|---:|---:|---|---|---:|---:|---:|---:|---:|\n\
| 20 | 0.5 | known start | factored | 1605 | 0.2819 | 0.2819 | 1.6e-15 | 11.4 |\n\
| 20 | 0.5 | known start | radon | 1605 | 0.3128 | 0.3362 | 1.0e0 | 9.2 |\n\
| 60 | 0.5 | known start | factored | 504 | 0.2473 | 0.2473 | 1.4e-15 | 13.0 |\n";

    #[test]
    fn the_rows_of_the_table_are_read_and_nothing_else() {
        let rows = rows_of(SAMPLE);
        assert_eq!(rows.len(), 3, "{rows:?}");
        assert_eq!(rows[1].belief, "radon");
        assert_eq!(rows[1].live, 0.3128);
        assert_eq!(rows[1].centralized, 0.3362);
        assert_eq!(rows[2].n, 60);
        assert_eq!(rows[2].largest, 1.4e-15);
    }

    #[test]
    fn the_committed_table_reads_back_as_it_was_written() {
        // The bench writes LiveRow::markdown; every row of the committed
        // file must come back from LiveRow::parse as the same line.
        let docs = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs"));
        let text = std::fs::read_to_string(docs.join(FILE)).unwrap();
        assert!(text.contains(TABLE_HEADER), "no table header in {FILE}");
        let mut rows = 0;
        for line in text.lines() {
            if let Some(row) = LiveRow::parse(line) {
                assert_eq!(row.markdown(), line);
                rows += 1;
            }
        }
        assert!(rows >= 36, "{rows} rows");
    }

    #[test]
    fn each_point_sets_the_live_beliefs_beside_the_centralized_ones() {
        let table = table(&rows_of(SAMPLE));
        assert!(
            table.contains("| known start | 0.5 | 20 | 1605 | 0.2819 | 0.2819 | 1.6e-15 | — | 0.3128 | 0.3362 |"),
            "{table}"
        );
        // A point without a Radon row says so rather than inventing one.
        assert!(
            table.contains(
                "| known start | 0.5 | 60 | 504 | 0.2473 | 0.2473 | 1.4e-15 | — | — | — |"
            ),
            "{table}"
        );
    }

    #[test]
    fn without_the_file_the_section_says_it_was_not_measured() {
        let dir = std::env::temp_dir().join(format!("idmesh-live-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let section = section(&dir);
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(section.contains("Not measured yet"), "{section}");
    }

    #[test]
    fn the_committed_results_carry_the_committed_live_accuracy() {
        // Regenerating live-accuracy.md (`idmesh bench --accuracy`) means
        // regenerating results.md (`idmesh eval --preset full --out-dir
        // docs`), which copies it.
        let docs = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../docs"));
        let committed = std::fs::read_to_string(docs.join("results.md")).unwrap();
        let section = section(docs);
        assert!(!section.contains("Not measured yet"), "{section}");
        assert!(
            committed.contains(&section),
            "docs/results.md does not carry docs/live-accuracy.md's table as it is now; \
             regenerate it with `cargo run --release -p idmesh-deploy -- eval --preset full \
             --out-dir docs`"
        );
    }
}
