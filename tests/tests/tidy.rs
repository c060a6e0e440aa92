//! Tidy: a ratchet on the size of what a reader must hold at once, as
//! TigerBeetle's tidy test keeps its code base.
//!
//! Every Rust file of the workspace's sources (`src/` of every crate; not
//! tests, benches, examples or `#[cfg(test)]` code, whose tables may run
//! long) is parsed, and:
//! - a function (free, method or nested) may hold at most
//!   [`FUNCTION_LINES`] lines of code,
//! - a file at most [`FILE_LINES`],
//!
//! counting lines that hold code: not blank, not only a comment. What is
//! over today is listed in `tests/tidy-exceptions.txt` with its size, and
//! the list may only shrink: the test fails on anything over the limit
//! that the list does not name, on a listed item that grew past its
//! listed size, and on a listed item that is no longer over (strike it).
//! `IDMESH_TIDY_BLESS=1` rewrites the list from what it finds (for moves
//! and renames; review the diff: it must not grow).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use syn::spanned::Spanned;
use syn::visit::Visit;

const FUNCTION_LINES: usize = 100;
const FILE_LINES: usize = 1200;
const EXCEPTIONS: &str = "tidy-exceptions.txt";

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_path_buf()
}

/// Every `.rs` file under a `src/` folder of the workspace, outside
/// `target/`, `fuzz/` and test modules kept in files of their own
/// (`tests.rs`, `tests/`).
fn sources(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().to_string();
            if path.is_dir() {
                let skip = name.starts_with('.')
                    || ["target", "fuzz", "node_modules"].contains(&name.as_str());
                if !skip {
                    stack.push(path);
                }
            } else if name.ends_with(".rs") {
                let rel = path.strip_prefix(root).expect("under the root");
                let parts: Vec<String> = rel
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().to_string())
                    .collect();
                let in_src = parts.iter().any(|p| p == "src");
                let test_file = name == "tests.rs"
                    || parts
                        .iter()
                        .skip_while(|p| *p != "src")
                        .any(|p| p == "tests");
                if in_src && !test_file {
                    out.push(path);
                }
            }
        }
    }
    out.sort();
    out
}

/// Whether a line holds code: not blank and not only a comment.
fn is_code(line: &str) -> bool {
    let t = line.trim();
    !(t.is_empty() || t.starts_with("//") || t.starts_with("/*") || t.starts_with('*'))
}

fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.parse_args::<syn::Meta>()
                .is_ok_and(|m| m.path().is_ident("test"))
    })
}

/// The functions of one file with their lines of code, and the lines of
/// `#[cfg(test)]` code (1-based, inclusive ranges) to leave out of the
/// file's count.
struct Walk<'a> {
    lines: &'a [&'a str],
    owner: Vec<String>,
    functions: Vec<(String, usize)>,
    test_ranges: Vec<(usize, usize)>,
}

impl Walk<'_> {
    fn code_lines(&self, from: usize, to: usize) -> usize {
        (from..=to)
            .filter_map(|l| self.lines.get(l - 1))
            .filter(|l| is_code(l))
            .count()
    }

    fn function(&mut self, name: &syn::Ident, sig: &syn::Signature, block: &syn::Block) {
        let from = sig.span().start().line;
        let to = block.span().end().line;
        let mut key = self.owner.clone();
        key.push(name.to_string());
        let size = self.code_lines(from, to);
        self.functions.push((key.join("::"), size));
    }
}

impl<'ast> Visit<'ast> for Walk<'_> {
    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        if is_cfg_test(&m.attrs) {
            self.test_ranges
                .push((m.span().start().line, m.span().end().line));
            return;
        }
        self.owner.push(m.ident.to_string());
        syn::visit::visit_item_mod(self, m);
        self.owner.pop();
    }

    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if is_cfg_test(&f.attrs) {
            self.test_ranges
                .push((f.span().start().line, f.span().end().line));
            return;
        }
        self.function(&f.sig.ident, &f.sig, &f.block);
        self.owner.push(f.sig.ident.to_string());
        syn::visit::visit_item_fn(self, f);
        self.owner.pop();
    }

    fn visit_item_impl(&mut self, i: &'ast syn::ItemImpl) {
        if is_cfg_test(&i.attrs) {
            self.test_ranges
                .push((i.span().start().line, i.span().end().line));
            return;
        }
        let ty = &i.self_ty;
        let name = quote_type(ty);
        self.owner.push(name);
        syn::visit::visit_item_impl(self, i);
        self.owner.pop();
    }

    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        if is_cfg_test(&f.attrs) {
            return;
        }
        self.function(&f.sig.ident, &f.sig, &f.block);
        self.owner.push(f.sig.ident.to_string());
        syn::visit::visit_impl_item_fn(self, f);
        self.owner.pop();
    }

    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(block) = &f.default {
            self.function(&f.sig.ident, &f.sig, block);
        }
        syn::visit::visit_trait_item_fn(self, f);
    }
}

/// A short name for an impl's self type: its last path segment.
fn quote_type(ty: &syn::Type) -> String {
    match ty {
        syn::Type::Path(p) => p
            .path
            .segments
            .last()
            .map_or_else(|| "_".to_string(), |s| s.ident.to_string()),
        syn::Type::Reference(r) => quote_type(&r.elem),
        _ => "_".to_string(),
    }
}

/// What is over a limit now: "fn <path>::<item path>" or "file <path>",
/// with its size.
fn measure(root: &Path) -> BTreeMap<String, usize> {
    let mut over = BTreeMap::new();
    for path in sources(root) {
        let rel = path
            .strip_prefix(root)
            .expect("under the root")
            .to_string_lossy()
            .replace('\\', "/");
        let text = std::fs::read_to_string(&path).expect("a readable source");
        let file =
            syn::parse_file(&text).unwrap_or_else(|e| panic!("{rel}: does not parse as Rust: {e}"));
        let lines: Vec<&str> = text.lines().collect();
        let mut walk = Walk {
            lines: &lines,
            owner: Vec::new(),
            functions: Vec::new(),
            test_ranges: Vec::new(),
        };
        walk.visit_file(&file);
        let mut seen: BTreeMap<String, usize> = BTreeMap::new();
        for (name, size) in &walk.functions {
            // Two functions of one name in one place (say, in two impls of
            // one generic type) are told apart by their order.
            let n = seen.entry(name.clone()).or_insert(0);
            *n += 1;
            let key = if *n == 1 {
                format!("fn {rel}::{name}")
            } else {
                format!("fn {rel}::{name}#{n}")
            };
            if *size > FUNCTION_LINES {
                over.insert(key, *size);
            }
        }
        let in_tests = |l: usize| walk.test_ranges.iter().any(|&(a, b)| (a..=b).contains(&l));
        let code = lines
            .iter()
            .enumerate()
            .filter(|(i, l)| !in_tests(i + 1) && is_code(l))
            .count();
        if code > FILE_LINES {
            over.insert(format!("file {rel}"), code);
        }
    }
    over
}

fn read_exceptions(path: &Path) -> BTreeMap<String, usize> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let (key, size) = l
                .rsplit_once(' ')
                .unwrap_or_else(|| panic!("{EXCEPTIONS}: `{l}` is not `<item> <size>`"));
            let size = size
                .parse()
                .unwrap_or_else(|_| panic!("{EXCEPTIONS}: `{l}`: the size is not a number"));
            (key.to_string(), size)
        })
        .collect()
}

/// What the list says against what was measured: the complaints.
fn compare(listed: &BTreeMap<String, usize>, found: &BTreeMap<String, usize>) -> Vec<String> {
    let mut problems = Vec::new();
    for (key, &size) in found {
        let limit = if key.starts_with("fn ") {
            FUNCTION_LINES
        } else {
            FILE_LINES
        };
        match listed.get(key) {
            None => problems.push(format!(
                "{key}: {size} lines of code, over the limit of {limit}: split it"
            )),
            Some(&was) if size > was => problems.push(format!(
                "{key}: grew from {was} to {size} lines of code (the list may only shrink)"
            )),
            Some(_) => {}
        }
    }
    for key in listed.keys().filter(|k| !found.contains_key(*k)) {
        problems.push(format!(
            "{key}: listed in tests/{EXCEPTIONS} but no longer over its limit (or gone): strike it"
        ));
    }
    problems
}

#[test]
fn functions_and_files_stay_within_their_limits() {
    let root = workspace();
    let found = measure(&root);
    let list = root.join("tests").join(EXCEPTIONS);
    if std::env::var("IDMESH_TIDY_BLESS").is_ok_and(|v| v == "1") {
        let mut text = format!(
            "# What is over tidy's limits today ({FUNCTION_LINES} lines of code a \
             function, {FILE_LINES} a file), with its size.\n# This list may only \
             shrink: see tests/tests/tidy.rs.\n"
        );
        for (key, size) in &found {
            text.push_str(&format!("{key} {size}\n"));
        }
        std::fs::write(&list, text).expect("write the exceptions");
        return;
    }
    let problems = compare(&read_exceptions(&list), &found);
    assert!(
        problems.is_empty(),
        "tidy: {} problem(s):\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// The measure sees a long function, a long method, a nested one and
/// skips test code; the comparison reports each kind of problem.
#[test]
fn tidy_reports_what_it_should() {
    let (dir, _scratch) = idmesh_tests::scratch("idmesh-tidy");
    let src = dir.join("demo").join("src");
    std::fs::create_dir_all(&src).expect("a scratch folder");
    let body = |n: usize| "    let _x = 1;\n".repeat(n);
    let text = format!(
        "fn long() {{\n{}}}\nstruct S;\nimpl S {{\n    fn method(&self) {{\n{}    }}\n}}\n\
         fn outer() {{\n    fn inner() {{\n{}    }}\n}}\n#[cfg(test)]\nmod tests {{\n    fn \
         ignored() {{\n{}    }}\n}}\n",
        body(FUNCTION_LINES + 1),
        body(FUNCTION_LINES + 2),
        body(FUNCTION_LINES + 3),
        body(FILE_LINES + 10),
    );
    std::fs::write(src.join("lib.rs"), text).expect("a scratch source");
    let found = measure(&dir);
    let keys: Vec<&str> = found.keys().map(String::as_str).collect();
    assert_eq!(
        keys,
        [
            "fn demo/src/lib.rs::S::method",
            "fn demo/src/lib.rs::long",
            "fn demo/src/lib.rs::outer",
            "fn demo/src/lib.rs::outer::inner",
        ],
        "{found:?}"
    );
    assert_eq!(found["fn demo/src/lib.rs::long"], FUNCTION_LINES + 3);
    let mut listed = found.clone();
    listed.remove("fn demo/src/lib.rs::long");
    listed.insert("fn demo/src/lib.rs::outer".into(), 5);
    listed.insert("fn demo/src/lib.rs::gone".into(), 500);
    let problems = compare(&listed, &found).join("\n");
    assert!(problems.contains("lib.rs::long: 103 lines"), "{problems}");
    assert!(
        problems.contains("lib.rs::outer: grew from 5"),
        "{problems}"
    );
    assert!(problems.contains("lib.rs::gone: listed"), "{problems}");
}
