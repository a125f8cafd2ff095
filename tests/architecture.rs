//! The layout as a test: the import graph of `src/` read from the sources.
//!
//! Every `use crate::…`, `use super::…` and inline `crate::…` path is resolved to the file of the
//! longest module prefix that exists, which gives a graph of files. The test then checks what
//! `src/sim/mod.rs`, `src/jobs/mod.rs` and `src/lib.rs` promise:
//! * no import cycle between the files of `src/sim/` or of `src/jobs/`;
//! * inside `src/sim/`, imports point down the layers math → model → engines → stats → solve →
//!   the root files (spec, document, runner, sweep) → checks;
//! * the core imports nothing outside `sim`, and the top-level modules form no cycle (in particular
//!   `api` and `server` do not import each other both ways);
//! * no file under `src/` is longer than 500 lines (the dashboard's vendored library excepted).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_LINES: usize = 500;

/// Layers of the core, lowest first; a file may import only files of its own or a lower layer.
const SIM_LAYERS: &[&[&str]] = &[
    &["math"],
    &["model"],
    &["engines"],
    &["stats"],
    &["solve"],
    &["spec", "document", "runner", "sweep", "mod"],
    &["checks"],
];

/// A source file and its module path (`["sim", "engines", "pixel"]`; `mod.rs` is its folder).
struct Source {
    module: Vec<String>,
    text: String,
}

fn sources() -> BTreeMap<PathBuf, Source> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut out = BTreeMap::new();
    let mut stack = vec![root.clone()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") && !path.to_string_lossy().ends_with("tests.rs") {
                let rel = path.strip_prefix(&root).unwrap().with_extension("");
                let mut module: Vec<String> = rel.iter().map(|c| c.to_string_lossy().into_owned()).collect();
                if module.last().is_some_and(|m| m == "mod" || m == "lib" || m == "main") {
                    module.pop();
                }
                let text = strip_comments(&std::fs::read_to_string(&path).unwrap());
                out.insert(rel, Source { module, text });
            }
        }
    }
    out
}

/// The source without line comments (doc comments mention paths that are not imports) and without
/// its test module (tests may build fixtures from any layer; they are not part of the layout).
fn strip_comments(text: &str) -> String {
    let text = text.find("#[cfg(test)]").map_or(text, |i| &text[..i]);
    text.lines()
        .map(|line| match line.find("//") {
            // Keep "//" inside string literals such as URLs: only cut a comment outside quotes.
            Some(i) if line[..i].matches('"').count() % 2 == 0 => &line[..i],
            _ => line,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Expands one `use` tree (`a::{b, c::{d, e}}`) into its paths.
fn expand(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else {
        let path = tree.split(" as ").next().unwrap().trim();
        return vec![path.trim_end_matches("::*").to_string()];
    };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.rfind('}').unwrap()];
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in inner.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&inner[start..]);
    parts
        .into_iter()
        .filter(|p| !p.trim().is_empty())
        .flat_map(expand)
        .map(|p| if p == "self" { prefix.trim_end_matches("::").to_string() } else { format!("{prefix}{p}") })
        .collect()
}

/// Every module path `text` refers to, absolute from the crate root.
fn referenced_paths(module: &[String], text: &str) -> Vec<Vec<String>> {
    let mut raw = Vec::new();
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let s = line.trim_start();
        let s = s.strip_prefix("pub(crate) ").or_else(|| s.strip_prefix("pub(super) ")).unwrap_or(s);
        let s = s.strip_prefix("pub ").unwrap_or(s);
        if s.starts_with("use ") {
            // The statement runs from here to its `;`, over as many lines as it takes.
            let start = offset + line.len() - s.len() + "use ".len();
            let end = start + text[start..].find(';').expect("a use statement ends with ;");
            raw.extend(expand(&text[start..end]));
        }
        offset += line.len();
    }
    // Inline paths, e.g. `crate::sim::engines::cost::MERGE_WEIGHT` inside an expression.
    for (i, _) in text.match_indices("crate::") {
        let rest = &text[i..];
        let end = rest.find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')).unwrap_or(rest.len());
        raw.push(rest[..end].trim_end_matches(':').to_string());
    }
    raw.into_iter()
        .filter_map(|path| {
            let segments: Vec<&str> = path.split("::").map(str::trim).collect();
            let mut base: Vec<String> = match segments[0] {
                "crate" => Vec::new(),
                // A `mod.rs` file's module is its folder, so `super` is one level up either way.
                "super" => module[..module.len().saturating_sub(1)].to_vec(),
                "self" => module.to_vec(),
                _ => return None,
            };
            let mut rest = &segments[1..];
            while rest.first() == Some(&"super") {
                base.pop();
                rest = &rest[1..];
            }
            base.extend(rest.iter().map(|s| s.to_string()));
            Some(base)
        })
        .collect()
}

/// The file a path refers to: the longest prefix of it that is a module.
fn resolve(path: &[String], modules: &BTreeMap<Vec<String>, PathBuf>) -> Option<PathBuf> {
    (0..=path.len()).rev().find_map(|n| modules.get(&path[..n]).cloned())
}

fn graph() -> (BTreeMap<PathBuf, Source>, BTreeMap<PathBuf, BTreeSet<PathBuf>>) {
    let sources = sources();
    let modules: BTreeMap<Vec<String>, PathBuf> =
        sources.iter().filter(|(p, _)| !p.ends_with("main")).map(|(p, s)| (s.module.clone(), p.clone())).collect();
    let mut edges: BTreeMap<PathBuf, BTreeSet<PathBuf>> = BTreeMap::new();
    for (path, source) in &sources {
        let targets = edges.entry(path.clone()).or_default();
        for referenced in referenced_paths(&source.module, &source.text) {
            if let Some(target) = resolve(&referenced, &modules)
                && target != *path
            {
                targets.insert(target);
            }
        }
    }
    (sources, edges)
}

/// The cycles (strongly connected components of more than one file) among `files`.
fn cycles(edges: &BTreeMap<PathBuf, BTreeSet<PathBuf>>, files: &BTreeSet<PathBuf>) -> Vec<Vec<PathBuf>> {
    // Two files are in one cycle when each reaches the other.
    let reach = |from: &PathBuf| -> BTreeSet<PathBuf> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(f) = stack.pop() {
            for t in edges.get(&f).into_iter().flatten().filter(|t| files.contains(*t)) {
                if seen.insert(t.clone()) {
                    stack.push(t.clone());
                }
            }
        }
        seen
    };
    let reaches: BTreeMap<&PathBuf, BTreeSet<PathBuf>> = files.iter().map(|f| (f, reach(f))).collect();
    let mut found: Vec<Vec<PathBuf>> = Vec::new();
    for f in files {
        let component: Vec<PathBuf> =
            files.iter().filter(|g| reaches[f].contains(*g) && reaches[*g].contains(f)).cloned().collect();
        if component.len() > 1 && !found.contains(&component) {
            found.push(component);
        }
    }
    found
}

fn under(sources: &BTreeMap<PathBuf, Source>, folder: &str) -> BTreeSet<PathBuf> {
    sources.iter().filter(|(_, s)| s.module.first().is_some_and(|m| m == folder)).map(|(p, _)| p.clone()).collect()
}

#[test]
fn the_files_of_the_core_and_of_the_job_runner_import_each_other_in_no_cycle() {
    let (sources, edges) = graph();
    for folder in ["sim", "jobs", "api", "server", "store", "cli"] {
        let files = under(&sources, folder);
        assert!(!files.is_empty(), "no files under src/{folder}");
        let found = cycles(&edges, &files);
        assert!(found.is_empty(), "import cycles in src/{folder}: {found:#?}");
    }
    // The check itself sees edges: the driver imports the job state, the runner the engines.
    assert!(edges[Path::new("jobs/driver")].contains(Path::new("jobs/state")));
    assert!(!edges[Path::new("jobs/driver")].contains(Path::new("jobs/manager")));
    assert!(edges[Path::new("sim/runner")].iter().any(|t| t.starts_with("sim/engines")));
}

#[test]
fn the_core_imports_point_down_its_layers() {
    let (sources, edges) = graph();
    let layer = |source: &Source| -> usize {
        let key = source.module.get(1).map_or("mod", String::as_str);
        SIM_LAYERS.iter().position(|names| names.contains(&key)).unwrap_or_else(|| panic!("{key} has no layer"))
    };
    let mut upward = Vec::new();
    for path in under(&sources, "sim") {
        for target in &edges[&path] {
            let (from, to) = (&sources[&path], &sources[target]);
            assert_eq!(to.module[0], "sim", "the core imports {target:?} from {path:?}: it must stay pure");
            // The root `sim/mod.rs` only declares the folders.
            if path != Path::new("sim/mod") && layer(to) > layer(from) {
                upward.push(format!("{} → {}", path.display(), target.display()));
            }
        }
    }
    assert!(upward.is_empty(), "imports pointing up the core's layers:\n{}", upward.join("\n"));
}

#[test]
fn the_top_level_modules_form_no_cycle() {
    let (sources, edges) = graph();
    let top = |p: &PathBuf| sources[p].module.first().cloned().unwrap_or_else(|| "lib".into());
    let mut modules: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (from, targets) in &edges {
        for to in targets {
            let (a, b) = (top(from), top(to));
            if a != b && a != "lib" && b != "lib" {
                modules.entry(a).or_default().insert(b);
            }
        }
    }
    let as_paths: BTreeMap<PathBuf, BTreeSet<PathBuf>> =
        modules.iter().map(|(a, bs)| (PathBuf::from(a), bs.iter().map(PathBuf::from).collect())).collect();
    let names: BTreeSet<PathBuf> = as_paths.keys().cloned().chain(as_paths.values().flatten().cloned()).collect();
    let found = cycles(&as_paths, &names);
    assert!(found.is_empty(), "top-level modules importing each other: {found:?} (graph: {modules:#?})");
    assert!(modules["server"].contains("api"), "the server wires the API");
    assert!(!modules.get("api").is_some_and(|m| m.contains("server")), "the API must not import the server");
}

#[test]
fn no_source_file_is_longer_than_500_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut long = Vec::new();
    let mut stack = vec![root.clone()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                // Third-party code kept as it was published.
                if !path.ends_with("vendor") {
                    stack.push(path);
                }
            } else {
                let lines = std::fs::read_to_string(&path).map_or(0, |t| t.lines().count());
                if lines > MAX_LINES {
                    long.push(format!("{} ({lines} lines)", path.strip_prefix(&root).unwrap().display()));
                }
            }
        }
    }
    assert!(long.is_empty(), "files over {MAX_LINES} lines: {long:?}");
}

#[test]
fn use_trees_expand_to_every_path() {
    let mut paths = expand("crate::sim::{math::rng::stream, model::{scene::Scene, params::{self, SceneSpec as S}}}");
    paths.sort();
    assert_eq!(
        paths,
        [
            "crate::sim::math::rng::stream",
            "crate::sim::model::params",
            "crate::sim::model::params::SceneSpec",
            "crate::sim::model::scene::Scene"
        ]
    );
}
