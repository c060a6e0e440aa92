//! `idmesh eval` as a user runs it: the real binary on the quick preset,
//! writing into a scratch directory; the tables and the SVG plots must be
//! there and well formed.

use idmesh_tests::idmesh;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Checks that `text` is well-formed XML as far as tags go: every element
/// opened is closed in order, one root, nothing after it.
fn check_xml(text: &str) -> Result<usize, String> {
    let mut stack: Vec<&str> = Vec::new();
    let mut elements = 0;
    let mut rest = text.trim();
    let mut closed_root = false;
    while let Some(start) = rest.find('<') {
        if closed_root && !rest[..start].trim().is_empty() {
            return Err("text after the root element".into());
        }
        let end = rest[start..]
            .find('>')
            .map(|e| start + e)
            .ok_or("a tag is not closed")?;
        let tag = &rest[start + 1..end];
        rest = &rest[end + 1..];
        if tag.starts_with('?') || tag.starts_with('!') {
            continue;
        }
        if closed_root {
            return Err(format!("element <{tag}> after the root"));
        }
        if let Some(name) = tag.strip_prefix('/') {
            match stack.pop() {
                Some(open) if open == name.trim() => {}
                other => return Err(format!("</{name}> closes {other:?}")),
            }
        } else {
            let name = tag
                .split(|c: char| c.is_whitespace() || c == '/')
                .next()
                .unwrap_or("");
            if name.is_empty() {
                return Err(format!("a tag without a name: <{tag}>"));
            }
            elements += 1;
            if !tag.ends_with('/') {
                stack.push(name);
            }
        }
        closed_root = stack.is_empty();
    }
    if !stack.is_empty() {
        return Err(format!("unclosed elements {stack:?}"));
    }
    Ok(elements)
}

#[test]
fn xml_checker_catches_bad_nesting() {
    assert_eq!(check_xml("<svg a=\"1\"><g><rect/></g></svg>"), Ok(3));
    assert!(check_xml("<svg><g></svg></g>").is_err());
    assert!(check_xml("<svg><g></g>").is_err());
}

#[test]
fn quick_eval_writes_tables_and_plots() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("eval-quick");
    let _ = std::fs::remove_dir_all(&dir);
    let binary = idmesh();
    let started = Instant::now();
    let output = Command::new(binary)
        .args(["eval", "--preset", "quick", "--out-dir"])
        .arg(&dir)
        .env_remove("RUST_LOG")
        .output()
        .expect("idmesh runs");
    let took = started.elapsed();
    assert!(
        output.status.success(),
        "idmesh eval failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(took.as_secs() < 60, "quick eval took {took:?}");

    // Table III on stdout: a row per method, at each n of the quick grid.
    let stdout = String::from_utf8(output.stdout).unwrap();
    assert!(stdout.contains("| method | n | tracking error | seconds | mean coeff. | max coeff. | paper error | paper seconds |"), "{stdout}");
    for row in [
        "| exact | 20 |",
        "| order 1 | 20 |",
        "| order 3 | 20 |",
        "| threshold (B = 100) | 20 |",
        "| overcomplete (B = 100) | 20 |",
        "| overcomplete, distributed rule (B = 100) | 20 |",
        "| particles, equal memory (P = B = 100) | 20 |",
        "| particles (P = 1000) | 20 |",
        "| factored | 20 |",
        "| particles, equal time to overcomplete (P = ",
    ] {
        assert!(stdout.contains(row), "no row {row} in\n{stdout}");
    }
    // Table III under both starts.
    for heading in [
        "Table III, swap 0.5, known start:",
        "Table III, swap 0.5, uniform prior:",
    ] {
        assert!(stdout.contains(heading), "no {heading} in\n{stdout}");
    }
    // The paper's numbers beside ours.
    assert!(
        stdout.contains("| 0.317 |") && stdout.contains("| 0.173 |"),
        "{stdout}"
    );

    // results.md: every section, and links to plots that exist.
    let md = std::fs::read_to_string(dir.join("results.md")).expect("results.md written");
    for section in [
        "# idmesh evaluation results",
        "--preset quick",
        "## Summary",
        "## Setup",
        "## Small scale",
        "## Table III",
        "### Known start, swap probability 0.5",
        "### Uniform prior, swap probability 0.5",
        "## Beating the paper: the factored belief",
        "## Sensitivity",
        "## The same table on real pedestrian scenes",
        "## Cost of the distributed conditioning rule",
        "## Against the particle filter at equal time",
        "## Against the particle filter at equal memory",
    ] {
        assert!(md.contains(section), "no `{section}` in results.md:\n{md}");
    }
    for method in ["| exact |", "| order 1 |", "| order 2 |", "| order 3 |"] {
        assert!(md.contains(method), "no row {method} in results.md");
    }
    // The distributed rule under both starts, and the goals with their
    // numbers filled in.
    for row in [
        "| n = 20, swap 0.5 | 20 | known start |",
        "| n = 20, swap 0.5 | 20 | uniform prior |",
        "| known start | 0.5 | factored |",
        "| known start | 0.5 | 20 |",
    ] {
        assert!(md.contains(row), "no row {row} in results.md:\n{md}");
    }
    assert!(
        !md.contains("NaN"),
        "a number is missing in results.md:\n{md}"
    );

    let svgs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .collect();
    let names: Vec<String> = svgs
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for want in [
        "results-mixing-n10.svg",
        "results-mixing-n20.svg",
        "results-swap.svg",
        "results-likelihood.svg",
    ] {
        assert!(names.iter().any(|n| n == want), "no {want} in {names:?}");
        assert!(
            md.contains(&format!("]({want})")),
            "results.md does not link {want}"
        );
    }
    for svg in &svgs {
        let text = std::fs::read_to_string(svg).unwrap();
        assert!(
            text.starts_with("<svg"),
            "{}: {}",
            svg.display(),
            &text[..20]
        );
        let elements = check_xml(&text).unwrap_or_else(|e| panic!("{}: {e}", svg.display()));
        assert!(elements > 20, "{}: only {elements} elements", svg.display());
        // One legend entry per method line, the exact filter among them.
        assert!(
            text.lines().any(|l| l.trim() == "exact"),
            "{}: no exact line",
            svg.display()
        );
        assert!(text.contains("overcomplete"), "{}", svg.display());
    }
}
