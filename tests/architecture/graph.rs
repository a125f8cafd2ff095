//! How `tests/architecture.rs` reads the import graph of `src/` from the sources (its module doc
//! says what counts as an edge): the files, their code without comments, literals and tests, the
//! paths they write, the types and `impl` blocks they hold, and the cycles of the graph.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

pub(super) type Edges = BTreeMap<PathBuf, BTreeSet<PathBuf>>;

/// A source file and its module path (`["sim", "engines", "pixel"]`; `mod.rs` is its folder).
pub(super) struct Source {
    pub(super) module: Vec<String>,
    /// The file as written: the promises are read from its module doc.
    pub(super) raw: String,
    /// The code only (see [`strip_code`]).
    pub(super) text: String,
}

/// Every source file under `src/` (tests files excepted), by path without extension.
pub(super) fn sources() -> BTreeMap<PathBuf, Source> {
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
                out.insert(rel.clone(), source(&rel, std::fs::read_to_string(&path).unwrap()));
            }
        }
    }
    out
}

/// The source at `rel` (a path under `src/` without its extension).
pub(super) fn source(rel: &Path, raw: String) -> Source {
    let mut module: Vec<String> = rel.iter().map(|c| c.to_string_lossy().into_owned()).collect();
    if module.last().is_some_and(|m| m == "mod" || m == "lib" || m == "main") {
        module.pop();
    }
    Source { module, text: strip_code(&raw), raw }
}

/// The code without comments (doc comments and their intra-doc links included), with every string
/// and character literal emptied (`""`, `' '`; lifetimes stay) and without `#[cfg(test)]` items.
/// Line breaks are kept, so a `use` statement still starts its line.
pub(super) fn strip_code(text: &str) -> String {
    let c: Vec<char> = text.chars().collect();
    let ident = |k: usize| c[k].is_alphanumeric() || c[k] == '_';
    let at = |k: usize, s: &str| s.chars().enumerate().all(|(j, x)| c.get(k + j) == Some(&x));
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    while i < c.len() {
        // A raw string: r"…", r#"…"#, br"…" or cr"…", where the `r` starts a token.
        let raw_start =
            c[i] == 'r' && (i == 0 || !ident(i - 1) || (matches!(c[i - 1], 'b' | 'c') && (i < 2 || !ident(i - 2))));
        let hashes = if raw_start { c[i + 1..].iter().take_while(|&&x| x == '#').count() } else { 0 };
        if at(i, "//") {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if at(i, "/*") {
            let mut depth = 0;
            while i < c.len() {
                if at(i, "/*") {
                    (depth, i) = (depth + 1, i + 2);
                } else if at(i, "*/") {
                    (depth, i) = (depth - 1, i + 2);
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.extend((c[i] == '\n').then_some('\n'));
                    i += 1;
                }
            }
        } else if raw_start && c.get(i + 1 + hashes) == Some(&'"') {
            let close: String = std::iter::once('"').chain(std::iter::repeat_n('#', hashes)).collect();
            i += 2 + hashes;
            while i < c.len() && !at(i, &close) {
                out.extend((c[i] == '\n').then_some('\n'));
                i += 1;
            }
            i += close.len();
            out.push_str("\"\"");
        } else if c[i] == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                out.extend((c[i] == '\n').then_some('\n'));
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if c[i] == '\'' && (c.get(i + 1) == Some(&'\\') || c.get(i + 2) == Some(&'\'')) {
            // A character literal ('x', '\n', '\'', '\u{..}'); a lifetime ('a) has no closing quote.
            i += 2;
            while i < c.len() && c[i] != '\'' {
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("' '");
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    // Test items: the attribute, then the item up to its `;` or through its braces.
    while let Some(start) = out.find("#[cfg(test)]") {
        let rest = &out[start..];
        let stop = rest.find([';', '{']).unwrap_or(rest.len() - 1);
        let end = start + if rest[stop..].starts_with('{') { stop + closing_brace(&rest[stop..]) } else { stop + 1 };
        let lines = "\n".repeat(out[start..end].matches('\n').count());
        out.replace_range(start..end, &lines);
    }
    out
}

/// The length of the braced block `text` starts with, through its closing brace.
fn closing_brace(text: &str) -> usize {
    let mut depth = 0;
    for (i, ch) in text.char_indices() {
        match ch {
            '{' => depth += 1,
            '}' if depth == 1 => return i + 1,
            '}' => depth -= 1,
            _ => {}
        }
    }
    text.len()
}

/// Expands one `use` tree (`a::{b, c::{d, e}}`) into its paths.
pub(super) fn expand(tree: &str) -> Vec<String> {
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

/// The paths of the `use` trees in `text` (stripped code), and the code without those statements.
fn use_paths(text: &str) -> (Vec<String>, String) {
    let (mut paths, mut code) = (Vec::new(), text.to_string());
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let s = line.trim_start();
        let s = match s.strip_prefix("pub(") {
            Some(v) => v.split_once(") ").map_or(s, |(_, rest)| rest),
            None => s.strip_prefix("pub ").unwrap_or(s),
        };
        if s.starts_with("use ") {
            // The statement runs from here to its `;`, over as many lines as it takes.
            let start = offset + line.len() - s.len();
            let end = start + text[start..].find(';').expect("a use statement ends with ;");
            paths.extend(expand(&text[start + "use ".len()..end]));
            code.replace_range(start..end, &" ".repeat(end - start));
        }
        offset += line.len();
    }
    (paths, code)
}

/// `path` as written in `module`, absolute from the crate root; None for a path that starts with
/// neither `crate`, `super` nor `self` (another crate's, or a child module's).
fn absolute(module: &[String], path: &str) -> Option<Vec<String>> {
    let segments: Vec<&str> = path.split("::").map(str::trim).collect();
    let mut base: Vec<String> = match segments[0] {
        "crate" | "$crate" => Vec::new(),
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
}

/// Every module path `text` (stripped code) refers to, absolute from the crate root: the paths of
/// its `use` trees, and the `crate::`, `super::` and `self::` paths written anywhere else.
pub(super) fn referenced_paths(module: &[String], text: &str) -> Vec<Vec<String>> {
    let (mut raw, code) = use_paths(text);
    // Inline paths, e.g. `super::illumination::Illumination::from_spec(spec)` inside an expression.
    for head in ["crate::", "super::", "self::"] {
        for (i, _) in code.match_indices(head) {
            let before = code[..i].chars().next_back();
            // Not inside a longer path (`super::super::x`) or another word, nor a visibility.
            if before.is_some_and(|b| b.is_alphanumeric() || b == '_' || b == ':') || code[..i].ends_with("pub(in ") {
                continue;
            }
            let rest = &code[i..];
            let end = rest.find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')).unwrap_or(rest.len());
            raw.push(rest[..end].trim_end_matches(':').to_string());
        }
    }
    raw.iter().filter_map(|path| absolute(module, path)).collect()
}

/// The names a module file brings into scope with `use`, and the absolute paths they stand for. A
/// path that starts with another name is read as its child module's (`pub use manager::JobManager`
/// in `jobs/mod.rs`); another crate's path then resolves to the file itself and leads nowhere.
fn imported_names(module: &[String], text: &str) -> BTreeMap<String, Vec<String>> {
    let relative = |p: &str| module.iter().cloned().chain(p.split("::").map(|s| s.trim().to_string())).collect();
    let paths = use_paths(text).0.into_iter().map(|p| absolute(module, &p).unwrap_or_else(|| relative(&p)));
    paths.filter_map(|p| Some((p.last()?.clone(), p))).collect()
}

/// The words of `code` (identifiers and keywords) with their byte offsets.
fn words(code: &str) -> Vec<(usize, &str)> {
    let is_word = |c: char| c.is_alphanumeric() || c == '_';
    let mut out = Vec::new();
    let mut start = None;
    for (i, c) in code.char_indices().chain(std::iter::once((code.len(), ' '))) {
        match (start, is_word(c)) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                out.push((s, &code[s..i]));
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// The types `code` defines (`struct`, `enum`, `trait`, `union`), and the functions of its
/// inherent `impl` blocks by type. Trait impls are left out: they may live anywhere, and calling
/// their methods needs the trait, which a path names.
fn types_and_methods(code: &str) -> (BTreeSet<String>, BTreeMap<String, BTreeSet<String>>) {
    let (mut types, mut methods) = (BTreeSet::new(), BTreeMap::<String, BTreeSet<String>>::new());
    let w = words(code);
    for (k, &(at, word)) in w.iter().enumerate() {
        let next = w.get(k + 1).map_or("", |n| n.1);
        if matches!(word, "struct" | "enum" | "trait" | "union") && next.starts_with(char::is_uppercase) {
            types.insert(next.to_string());
        }
        // An `impl` item starts its line (`x: impl Trait` is a type, not an item).
        let line_start = code[..at].rfind('\n').map_or(0, |n| n + 1);
        if word != "impl" || !matches!(code[line_start..at].trim(), "" | "unsafe") {
            continue;
        }
        let Some(open) = code[at..].find('{').map(|o| at + o) else { continue };
        let mut header = code[at + "impl".len()..open].trim();
        if header.starts_with('<') {
            header = &header[closing_angle(header)..];
        }
        let header = header.split(" where").next().unwrap().split("\nwhere").next().unwrap().trim();
        if words(header).iter().any(|&(_, x)| x == "for") {
            continue;
        }
        let name = header.split('<').next().unwrap().rsplit("::").next().unwrap().trim();
        let body = &code[open..open + closing_brace(&code[open..])];
        let body_words = words(body);
        let fns = body_words.windows(2).filter(|p| p[0].1 == "fn").map(|p| p[1].1.to_string());
        methods.entry(name.to_string()).or_default().extend(fns);
    }
    (types, methods)
}

/// The length of the generic parameters `text` starts with (`<T: Into<U>>`), through the `>`.
fn closing_angle(text: &str) -> usize {
    let mut depth = 0;
    for (i, ch) in text.char_indices() {
        match ch {
            '<' => depth += 1,
            // The arrow of a closure bound (`W: FnMut(&[u8]) -> Result<(), E>`) closes nothing.
            '>' if text[..i].ends_with('-') => {}
            '>' if depth == 1 => return i + 1,
            '>' => depth -= 1,
            _ => {}
        }
    }
    text.len()
}

/// Module paths and their files, and the names each file imports.
struct Modules {
    files: BTreeMap<Vec<String>, PathBuf>,
    imports: BTreeMap<PathBuf, BTreeMap<String, Vec<String>>>,
}

impl Modules {
    fn of(sources: &BTreeMap<PathBuf, Source>) -> Self {
        // `main.rs` is the binary's root, not the library's: paths never lead there.
        let lib = sources.iter().filter(|(p, _)| !p.ends_with("main"));
        Modules {
            files: lib.map(|(p, s)| (s.module.clone(), p.clone())).collect(),
            imports: sources.iter().map(|(p, s)| (p.clone(), imported_names(&s.module, &s.text))).collect(),
        }
    }

    /// The file a path refers to: the longest prefix of it that is a module, or, when the next name
    /// is one that module imports (a re-export such as `crate::jobs::JobManager`), where it leads.
    fn resolve(&self, path: &[String], depth: usize) -> Option<PathBuf> {
        let n = (0..=path.len()).rev().find(|&n| self.files.contains_key(&path[..n]))?;
        let file = &self.files[&path[..n]];
        let imported = path.get(n).and_then(|name| self.imports[file].get(name));
        if let Some(target) = imported.filter(|t| depth < 8 && !path.starts_with(t))
            && let Some(further) = self.resolve(&[target, &path[n + 1..]].concat(), depth + 1)
        {
            return Some(further);
        }
        Some(file.clone())
    }
}

pub(super) fn graph() -> (BTreeMap<PathBuf, Source>, Edges) {
    let sources = sources();
    let edges = edges_of(&sources);
    (sources, edges)
}

/// The import graph of `sources`: the files their paths lead to. Method calls need no edges of
/// their own: every type's inherent `impl` blocks are in the file that defines it
/// ([`stray_impls`] finds any that are not), so the path that names a type — or the path to
/// whatever hands out a value of it — already leads to every method it has.
pub(super) fn edges_of(sources: &BTreeMap<PathBuf, Source>) -> Edges {
    let modules = Modules::of(sources);
    let mut edges = Edges::new();
    for (path, source) in sources {
        let targets = edges.entry(path.clone()).or_default();
        let referenced = referenced_paths(&source.module, &source.text);
        targets.extend(referenced.iter().filter_map(|r| modules.resolve(r, 0)));
        targets.remove(path);
    }
    edges
}

/// Inherent `impl` blocks outside the file that defines their type, as "file: impl Type".
pub(super) fn stray_impls(sources: &BTreeMap<PathBuf, Source>) -> Vec<String> {
    let mut stray = Vec::new();
    for (path, source) in sources {
        let (types, methods) = types_and_methods(&source.text);
        for ty in methods.keys().filter(|ty| !types.contains(*ty)) {
            stray.push(format!("src/{}.rs: impl {ty}", path.display()));
        }
    }
    stray
}

/// The cycles (strongly connected components of more than one file) among `files`.
pub(super) fn cycles(edges: &Edges, files: &BTreeSet<PathBuf>) -> Vec<Vec<PathBuf>> {
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
