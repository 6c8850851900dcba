//! The library's layers, checked on its source: data flows one way (docs/DESIGN.md, "Layers"),
//! so no module imports one above it, and no two files import each other in a loop.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The library's top-level modules from the bottom up. A module may import only those on lower
/// rows; modules on one row do not import each other.
const LAYERS: &[&[&str]] = &[
    &["math", "error"],
    &["io", "geometry"],
    &["scene"],
    &["photo"],
    &["render"],
    &["prepare"],
    &["fit"],
    &["report", "export", "import"],
    &["api"],
    &["fuzzing"],
];

fn rank(module: &str) -> Option<usize> {
    LAYERS.iter().position(|row| row.contains(&module))
}

/// One source file of the library: its module path (`fit::cache::build`) and its code without
/// comments and without its unit tests.
struct Source {
    module: Vec<String>,
    code: String,
    path: PathBuf,
}

fn sources() -> Vec<Source> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../src");
    let mut files = Vec::new();
    walk(&src, &mut files);
    files.sort();
    files
        .into_iter()
        .filter_map(|path| {
            let rel = path.strip_prefix(&src).unwrap().with_extension("");
            let mut module: Vec<String> = rel.iter().map(|c| c.to_string_lossy().into()).collect();
            if module.last().is_some_and(|m| m == "mod") {
                module.pop();
            }
            // lib.rs is the list.
            if module.is_empty() || module[0] == "lib" {
                return None;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            // Its unit tests, a module of its own at the end, are not part of the library.
            let text = ["#[cfg(test)]\nmod ", "#[cfg(test)]\npub(crate) mod "]
                .iter()
                .filter_map(|m| text.find(m))
                .min()
                .map_or(&text[..], |i| &text[..i]);
            let code = text
                .lines()
                .filter(|l| !l.trim_start().starts_with("//"))
                .collect::<Vec<_>>()
                .join("\n");
            Some(Source { module, code, path })
        })
        .collect()
}

/// The `crate::a::b::…` paths a file names, resolved from `super::` where it uses that, as
/// lists of segments (`use crate::fit::{cache, event::Event}` gives `fit::cache` and
/// `fit::event::Event`).
fn references(s: &Source) -> Vec<Vec<String>> {
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut out = Vec::new();
    let code = &s.code;
    let mut i = 0;
    while i < code.len() {
        let rest = &code[i..];
        let (base, skip): (Vec<String>, usize) = if rest.starts_with("crate::") {
            (Vec::new(), "crate::".len())
        } else if rest.starts_with("super::")
            && (i == 0 || !ident(code[..i].chars().last().unwrap()))
        {
            // super:: names the parent of the module the file is (a mod.rs is its folder's).
            let mut base = s.module.clone();
            let mut skip = 0;
            let mut r = rest;
            while let Some(t) = r.strip_prefix("super::") {
                base.pop();
                skip += "super::".len();
                r = t;
            }
            (base, skip)
        } else {
            i += rest.chars().next().unwrap().len_utf8();
            continue;
        };
        if i > 0 && ident(code[..i].chars().last().unwrap()) {
            i += skip;
            continue;
        }
        let tail = &rest[skip..];
        let end = tail
            .find(|c: char| !(ident(c) || c == ':'))
            .unwrap_or(tail.len());
        let mut path = base.clone();
        path.extend(
            tail[..end]
                .split("::")
                .filter(|x| !x.is_empty())
                .map(String::from),
        );
        // A brace list: each item under the prefix.
        if tail[end..].starts_with('{') && tail[..end].ends_with("::") {
            let close = tail[end..].find('}').map(|c| end + c).unwrap_or(tail.len());
            for item in tail[end + 1..close].split(',') {
                let item: String = item
                    .trim()
                    .chars()
                    .take_while(|&c| ident(c) || c == ':')
                    .collect();
                let mut p = path.clone();
                p.extend(
                    item.split("::")
                        .filter(|x| !x.is_empty() && *x != "self")
                        .map(String::from),
                );
                out.push(p);
            }
        } else {
            out.push(path);
        }
        i += skip + end;
    }
    out
}

#[test]
fn no_module_imports_a_layer_above_its_own() {
    let mut upward = Vec::new();
    for s in sources() {
        let Some(own) = rank(&s.module[0]) else {
            panic!("{}: a top-level module not in LAYERS", s.path.display());
        };
        for r in references(&s) {
            let Some(to) = r.first() else { continue };
            if *to == s.module[0] {
                continue;
            }
            match rank(to) {
                Some(k) if k < own => {}
                _ => upward.push(format!("{} -> crate::{}", s.path.display(), r.join("::"))),
            }
        }
    }
    upward.sort();
    upward.dedup();
    assert!(
        upward.is_empty(),
        "imports that run upward or sideways:\n{}",
        upward.join("\n")
    );
}

#[test]
fn no_two_files_import_each_other_in_a_loop() {
    let sources = sources();
    let modules: BTreeSet<Vec<String>> = sources.iter().map(|s| s.module.clone()).collect();
    // A folder's mod.rs that only hands its children's names on (`pub use child::Name`): a
    // reference to `folder::Name` is one to the child.
    let mut faces: BTreeMap<(Vec<String>, String), Vec<String>> = BTreeMap::new();
    for s in &sources {
        for line in s.code.lines() {
            let Some(rest) = line.trim().strip_prefix("pub use ") else {
                continue;
            };
            let rest = rest.trim_end_matches(';');
            let (child, names) = match rest.split_once("::{") {
                Some((c, n)) => (c, n.trim_end_matches('}').to_string()),
                None => match rest.rsplit_once("::") {
                    Some((c, n)) => (c, n.to_string()),
                    None => continue,
                },
            };
            if child.contains(':') && !child.starts_with("crate::") {
                continue;
            }
            let mut target = s.module.clone();
            target.extend(child.split("::").map(String::from));
            for n in names.split(',') {
                let n = n
                    .trim()
                    .split(" as ")
                    .last()
                    .unwrap_or("")
                    .trim()
                    .to_string();
                faces.insert((s.module.clone(), n), target.clone());
            }
        }
    }
    // Each reference resolves to the longest module path it starts with, through faces.
    let resolve = |r: &[String]| -> Option<Vec<String>> {
        let mut best = None;
        for k in (1..=r.len()).rev() {
            if modules.contains(&r[..k]) {
                best = Some(r[..k].to_vec());
                if let Some(name) = r.get(k) {
                    if let Some(t) = faces.get(&(r[..k].to_vec(), name.clone())) {
                        if modules.contains(t) {
                            best = Some(t.clone());
                        }
                    }
                }
                break;
            }
        }
        best
    };
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for s in &sources {
        for r in references(s) {
            if let Some(t) = resolve(&r) {
                // A face's own re-exports of its children are not imports of them.
                let child_of_face = t.len() > s.module.len() && t.starts_with(&s.module);
                if t != s.module && !child_of_face {
                    edges.entry(s.module.clone()).or_default().insert(t);
                }
            }
        }
    }
    // Depth-first search for a cycle.
    fn visit(
        m: &Vec<String>,
        edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        state: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<Vec<String>>> {
        match state.get(m) {
            Some(2) => return None,
            Some(1) => {
                let i = stack.iter().position(|x| x == m).unwrap();
                return Some(stack[i..].to_vec());
            }
            _ => {}
        }
        state.insert(m.clone(), 1);
        stack.push(m.clone());
        for t in edges.get(m).into_iter().flatten() {
            if let Some(c) = visit(t, edges, state, stack) {
                return Some(c);
            }
        }
        stack.pop();
        state.insert(m.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in &modules {
        let mut stack = Vec::new();
        if let Some(cycle) = visit(m, &edges, &mut state, &mut stack) {
            let names: Vec<String> = cycle.iter().map(|c| c.join("::")).collect();
            panic!(
                "files that import each other in a loop: {}",
                names.join(" -> ")
            );
        }
    }
}
