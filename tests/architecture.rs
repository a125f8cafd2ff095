//! The layout as a test: the import graph of `src/` read from the sources, and the promises the
//! folders make about it.
//!
//! # The graph
//!
//! One node per file, an edge A → B when A's code names something of B. The sources are read
//! without comments (doc comments and their intra-doc links included), with every string and
//! character literal emptied and without their `#[cfg(test)]` items (tests may build fixtures from
//! any layer; they are not part of the layout). Then:
//! * **paths**: every path that starts with `crate::`, `super::` or `self::` — in a `use` tree or
//!   inline in code, such as `super::illumination::Illumination::from_spec(..)` in a function body —
//!   is resolved to the file of the longest module prefix that exists;
//! * **re-exports**: a path through a module file to a name that file imports leads on to where
//!   the name comes from (`crate::jobs::JobManager` reaches `jobs/core/manager.rs`, which `jobs/mod.rs`
//!   re-exports it from). A module file's own `use child::…` paths (without `self::`) are read for
//!   that only: a module file declares its children, so they are not edges of their own;
//! * **methods** need no rule of their own: every type's inherent `impl` blocks are in the file
//!   that defines it (checked below), so whatever names a type — or names what hands out a value
//!   of it — reaches every method the type has. No method name is skipped or guessed.
//!
//! # What it checks
//! * no import cycle among the files of `src/` (the failure lists every cycle with its files);
//! * every folder keeps the promise of its module file (`mod.rs`, or `lib.rs` for the files at the
//!   top of `src/`): a line `//! Imports: crate::sim, crate::store` — or `//! Imports: nothing from
//!   the crate` — lists the crate modules the folder's files (subfolders included) may import
//!   besides the folder's own files;
//! * the core imports nothing outside `src/sim/`, and inside it imports point down the layers
//!   math → model → engines → stats → solve → the root files (spec, configuration, document, signature, runner, sweep) →
//!   checks;
//! * every type's inherent `impl` blocks are in the file that defines the type;
//! * the job runner's rooms point down [`JOB_ROOMS`]: the lifecycle core (`jobs/core/`) is the
//!   ground and imports no feature, and no folder of `jobs/` has more than [`MAX_ROOM_EDGES`]
//!   import edges between its parts (a subfolder counts as one part of its parent);
//! * the top-level modules form no cycle (in particular `api` and `server` do not import each
//!   other both ways);
//! * no file under `src/` is longer than 500 lines (the dashboard's vendored library excepted).

mod graph;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use graph::{
    Edges, Source, cycles, edges_of, expand, graph, referenced_paths, source, sources, stray_impls, strip_code,
};

const MAX_LINES: usize = 500;

/// Layers of the core, lowest first; a file may import only files of its own or a lower layer.
const SIM_LAYERS: &[&[&str]] = &[
    &["math"],
    &["model"],
    &["engines"],
    &["stats"],
    &["solve"],
    &["spec", "configuration", "document", "signature", "runner", "sweep", "weights", "mod"],
    &["checks"],
];

/// The rooms of `jobs/`, lowest first: a room imports only rooms of lower layers (and its own
/// files). The core is the ground; each feature is a service on it.
const JOB_ROOMS: &[&[&str]] = &[
    &["core"],
    &["cluster", "statistics"],
    &["merges", "artifacts", "evaluation", "solves", "prediction"],
    &["sweeps"],
    &["services", "mod"],
];

/// Most import edges between the parts of one folder of `jobs/`.
const MAX_ROOM_EDGES: usize = 45;

/// How a folder's module file states what the folder may import (one line of its module doc).
const PROMISE: &str = "//! Imports: ";
/// The promise of a folder that imports nothing from the crate outside itself.
const NOTHING: &str = "nothing from the crate";

fn under(sources: &BTreeMap<PathBuf, Source>, folder: &str) -> BTreeSet<PathBuf> {
    sources.iter().filter(|(_, s)| s.module.first().is_some_and(|m| m == folder)).map(|(p, _)| p.clone()).collect()
}

/// A cycle as the failure shows it: its files, and the edges that close it.
fn describe(cycle: &[PathBuf], edges: &Edges) -> String {
    let mut out = format!("{} files:", cycle.len());
    for from in cycle {
        let to: Vec<String> =
            edges[from].iter().filter(|t| cycle.contains(t)).map(|t| format!("src/{}.rs", t.display())).collect();
        out += &format!("\n    src/{}.rs → {}", from.display(), to.join(", "));
    }
    out
}

#[test]
fn no_files_of_the_crate_import_each_other_in_a_cycle() {
    let (sources, edges) = graph();
    for folder in ["sim", "jobs", "api", "server", "store", "cli"] {
        assert!(!under(&sources, folder).is_empty(), "no files under src/{folder}");
    }
    let found = cycles(&edges, &sources.keys().cloned().collect());
    let listed: Vec<String> = found.iter().map(|c| describe(c, &edges)).collect();
    assert!(found.is_empty(), "{} import cycles in src/:\n  {}", found.len(), listed.join("\n  "));
    // The check itself sees edges: the driver imports the job state, the runner the engines.
    assert!(edges[Path::new("jobs/core/driver")].contains(Path::new("jobs/core/state")));
    assert!(!edges[Path::new("jobs/core/driver")].contains(Path::new("jobs/core/manager")));
    assert!(edges[Path::new("sim/runner")].iter().any(|t| t.starts_with("sim/engines")));
}

/// The promise in a module file's doc: `None` without the line, else the crate modules it lists.
fn promise(raw: &str) -> Option<Result<Vec<Vec<String>>, String>> {
    let line = raw.lines().find_map(|l| l.strip_prefix(PROMISE))?.trim();
    if line == NOTHING {
        return Some(Ok(Vec::new()));
    }
    let parse = |p: &str| match p.trim().strip_prefix("crate::") {
        Some(module) => Ok(module.split("::").map(String::from).collect()),
        None => Err(format!("`{}` is not a crate module (`crate::…`, or the line says `{NOTHING}`)", p.trim())),
    };
    Some(line.split(',').map(parse).collect())
}

#[test]
fn every_folder_keeps_the_import_promise_of_its_module_file() {
    let (sources, edges) = graph();
    let folders: BTreeSet<&Path> = sources.keys().filter_map(|p| p.parent()).collect();
    let mut broken = Vec::new();
    for folder in folders {
        // The root's files are `lib.rs` and its neighbours; every other folder is a module with
        // its subfolders, whose module file is its `mod.rs` (or the `.rs` file beside it).
        let root = folder.as_os_str().is_empty();
        let module_file = match folder.join("mod") {
            _ if root => PathBuf::from("lib"),
            mod_rs if sources.contains_key(&mod_rs) => mod_rs,
            _ => folder.to_path_buf(),
        };
        assert!(sources.contains_key(&module_file), "src/{}/ has no module file", folder.display());
        let shown = format!("src/{}.rs", module_file.display());
        let allowed = match promise(&sources[&module_file].raw) {
            None => {
                let files =
                    if root { "the files at the top of src/".into() } else { format!("src/{}/", folder.display()) };
                broken.push(format!(
                    "{shown} has no `{PROMISE}…` line saying which crate modules {files} may import (e.g. \
                     `{PROMISE}crate::sim, crate::store` or `{PROMISE}{NOTHING}`)"
                ));
                continue;
            }
            Some(Err(e)) => {
                broken.push(format!("{shown}: {e}"));
                continue;
            }
            Some(Ok(allowed)) => allowed,
        };
        let inside = |p: &Path| if root { p.parent() == Some(folder) } else { p.starts_with(folder) };
        for (from, targets) in edges.iter().filter(|(p, _)| inside(p)) {
            for to in targets.iter().filter(|t| !inside(t)) {
                if !allowed.iter().any(|m| sources[to].module.starts_with(m)) {
                    broken.push(format!(
                        "src/{}.rs imports src/{}.rs: not promised by {shown}",
                        from.display(),
                        to.display()
                    ));
                }
            }
        }
    }
    assert!(broken.is_empty(), "folders breaking their import promise:\n{}", broken.join("\n"));
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
    let as_paths: Edges =
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

#[test]
fn inline_paths_count_and_comments_and_literals_do_not() {
    let text = r##"//! See [`super::a`].
/// Calls [`super::b::f`] /* and super::c */ too.
pub(crate) use super::d::{self, D};
fn f<'a>(x: &'a str) -> char {
    let _ = ("super::e", r#"crate::f "x""#, '"', '\'', super::g::G::new(x));
    crate::h::H::run(); /* nested /* super::i */ super::j */ 'k'
}
pub(in crate::m) fn g() {}
#[cfg(test)]
mod tests { use super::l; }
"##;
    let module = ["m".to_string(), "n".to_string()];
    let mut read: Vec<String> = referenced_paths(&module, &strip_code(text)).iter().map(|p| p.join("::")).collect();
    read.sort();
    assert_eq!(read, ["h::H::run", "m::d", "m::d::D", "m::g::G::new"]);
}

#[test]
fn an_impl_block_away_from_its_type_is_found() {
    let files = [
        ("a/mod", "pub struct Hub;\nimpl Hub {\n    fn run(&self) {}\n}\nimpl std::fmt::Debug for Hub {}\n"),
        ("a/check", "use super::Hub;\nimpl Hub {\n    pub fn check(&self) {}\n}\n"),
        (
            "a/saver",
            "pub struct Saver<W>(W);\nimpl<W: FnMut(&[u8]) -> Result<(), ()>> Saver<W> {\n    fn go(&self) {}\n}\n",
        ),
    ];
    let sources = files.iter().map(|(p, t)| (PathBuf::from(p), source(Path::new(p), t.to_string()))).collect();
    assert_eq!(stray_impls(&sources), ["src/a/check.rs: impl Hub"]);
}

#[test]
fn a_path_through_a_re_export_reaches_the_file_that_defines_the_name() {
    let files = [
        ("a/mod", "mod inner;\npub use inner::Thing;\n"),
        ("a/inner", "pub struct Thing;\n"),
        ("b/user", "fn go() -> crate::a::Thing { crate::a::Thing }\n"),
    ];
    let sources = files.iter().map(|(p, t)| (PathBuf::from(p), source(Path::new(p), t.to_string()))).collect();
    let edges = edges_of(&sources);
    assert_eq!(edges[Path::new("b/user")], BTreeSet::from([PathBuf::from("a/inner")]), "{edges:?}");
    assert!(edges[Path::new("a/mod")].is_empty(), "a module file's children are not its imports: {edges:?}");
}

#[test]
fn every_types_inherent_impl_blocks_are_in_the_file_that_defines_it() {
    let stray = stray_impls(&sources());
    assert!(
        stray.is_empty(),
        "inherent impl blocks away from the file that defines their type (move them there, or make the \
         operation a type of its own):\n{}",
        stray.join("\n")
    );
}

/// A file's room in `jobs/` (`core`, `merges`, `statistics`, …), None outside `jobs/`.
fn room(source: &Source) -> Option<&str> {
    (source.module.first()? == "jobs").then(|| source.module.get(1).map_or("mod", String::as_str))
}

/// What breaks the rooms of `jobs/`: imports up or across the layers, the core importing a
/// feature, a folder with too many edges between its parts. Also the edge count of each folder.
fn job_room_violations(sources: &BTreeMap<PathBuf, Source>, edges: &Edges) -> (Vec<String>, BTreeMap<String, usize>) {
    let layer = |room: &str| JOB_ROOMS.iter().position(|l| l.contains(&room));
    let mut broken = Vec::new();
    for (from, targets) in edges {
        let Some(a) = room(&sources[from]) else { continue };
        let la = layer(a).unwrap_or_else(|| panic!("jobs/{a} has no layer in JOB_ROOMS"));
        for to in targets {
            let Some(b) = room(&sources[to]) else { continue };
            let lb = layer(b).unwrap_or_else(|| panic!("jobs/{b} has no layer in JOB_ROOMS"));
            if a != b && (lb > la || (lb == la && a != "mod")) {
                let how = if a == "core" { "the core imports a feature" } else { "an import up or across the rooms" };
                broken.push(format!("{how}: src/{}.rs → src/{}.rs", from.display(), to.display()));
            }
        }
    }
    // Edges between the parts of each folder of jobs/: its files, and its subfolders as one part.
    let mut counts = BTreeMap::new();
    let folders: BTreeSet<Vec<String>> = sources
        .values()
        .filter(|s| s.module.first().is_some_and(|m| m == "jobs"))
        .flat_map(|s| (1..s.module.len()).map(|n| s.module[..n].to_vec()))
        .collect();
    for folder in folders {
        let part = |s: &Source| {
            (s.module.len() > folder.len() && s.module.starts_with(&folder)).then(|| s.module[folder.len()].clone())
        };
        let mut between = BTreeSet::new();
        for (from, targets) in edges {
            for to in targets {
                if let (Some(a), Some(b)) = (part(&sources[from]), part(&sources[to]))
                    && a != b
                {
                    between.insert((a, b));
                }
            }
        }
        let name = format!("src/{}/", folder.join("/"));
        if between.len() > MAX_ROOM_EDGES {
            broken.push(format!(
                "{name} has {} import edges between its parts (at most {MAX_ROOM_EDGES})",
                between.len()
            ));
        }
        counts.insert(name, between.len());
    }
    (broken, counts)
}

#[test]
fn the_job_rooms_point_down_from_features_to_a_core_that_knows_none() {
    let (sources, edges) = graph();
    let (broken, counts) = job_room_violations(&sources, &edges);
    let all = edges.iter().filter(|(f, _)| room(&sources[*f]).is_some());
    let flat = all.map(|(_, t)| t.iter().filter(|t| room(&sources[*t]).is_some()).count()).sum::<usize>();
    eprintln!("import edges between the parts of each folder of jobs/: {counts:?}; between all its files: {flat}");
    assert!(broken.is_empty(), "the rooms of jobs/ are broken:\n{}", broken.join("\n"));
    let jobs = sources.iter().filter(|(_, s)| room(s).is_some()).map(|(p, _)| p.clone()).collect();
    assert!(cycles(&edges, &jobs).is_empty(), "import cycles in jobs/");
    assert!(counts["src/jobs/"] > 0 && counts["src/jobs/core/"] > 0, "the count sees edges: {counts:?}");
}

/// The probes of issue 43: a call from the core's driver back to the manager (a cycle manager →
/// scheduler → driver → manager), and a call from the core to a feature, each fail the layout.
#[test]
fn a_call_from_a_lower_job_room_to_a_higher_one_fails_the_layout() {
    let probes = [
        ("jobs/core/driver", "fn probe(jobs: &super::manager::JobManager) { let _ = jobs.cancel(1); }"),
        ("jobs/core/driver", "fn probe(jobs: &crate::jobs::JobManager) { let _ = jobs.cancel(1); }"),
        ("jobs/core/resource", "fn probe(s: &crate::jobs::statistics::Statistics) { let _ = s.result(1); }"),
        ("jobs/statistics", "fn probe(s: &super::sweeps::Sweeps) { let _ = s.get(1); }"),
        ("jobs/cluster/executor", "fn probe(m: &crate::jobs::merges::Merges) { let _ = m.clone(); }"),
    ];
    let (plain, edges) = graph();
    assert!(job_room_violations(&plain, &edges).0.is_empty(), "the rooms hold before the probes");
    assert!(cycles(&edges, &plain.keys().cloned().collect()).is_empty(), "no cycle before the probes");
    for (file, probe) in probes {
        let mut probed = sources();
        let target = probed.get_mut(Path::new(file)).unwrap_or_else(|| panic!("no src/{file}.rs"));
        target.text.push_str(&format!("\n{}\n", strip_code(probe)));
        let edges = edges_of(&probed);
        let cycles = cycles(&edges, &probed.keys().cloned().collect());
        let (broken, _) = job_room_violations(&probed, &edges);
        assert!(!cycles.is_empty() || !broken.is_empty(), "the probe `{probe}` in src/{file}.rs went unnoticed");
    }
}
