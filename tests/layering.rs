//! The floors of the tree (ARCHITECTURE.md, "Layers"), enforced as rust-analyzer's tidy
//! tests enforce theirs: every `crate::…` and `super::…` path in `src/` outside test code is
//! read, resolved to the module file it names, and checked against the layer order below;
//! and no module file may reach itself through others (no import cycles, at any depth).
//!
//! Test code does not count: a file's tail from `#[cfg(test)]` before `mod tests`, and files
//! declared under `#[cfg(test)]` (`physics/validation.rs`, the `#[path]` test files).
//! Comments do not count (a doc link is not an import).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The top-level modules, bottom to top: each may use only those before it.
const LAYERS: [&str; 20] = [
    "physics",
    "signal",
    "synth",
    "daq",
    "simdevice",
    "recipe",
    "estimate",
    "alert",
    "advise",
    "report",
    "identify",
    "record",
    "pipeline",
    "acquire",
    "config",
    "session",
    "history",
    "diagnose",
    "daemon",
    "cli",
];

/// A module file's path from `src/`: `a::b` for `src/a/b.rs` and `src/a/b/mod.rs`.
fn module_of(rel: &Path) -> String {
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" {
        parts.push(stem.to_owned());
    }
    parts.join("::")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("src/ is readable") {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Files a `#[cfg(test)]` module declaration brings in, relative to `src/`.
fn test_only_files(rel: &Path, text: &str) -> Vec<PathBuf> {
    let dir = match rel.file_name().and_then(|f| f.to_str()) {
        Some("mod.rs" | "lib.rs" | "main.rs") => rel.parent().unwrap_or(Path::new("")).to_path_buf(),
        _ => rel.with_extension(""),
    };
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let Some(name) = line.strip_prefix("mod ").and_then(|l| l.strip_suffix(';')) else { continue };
        let attrs = &lines[i.saturating_sub(2)..i];
        if !attrs.contains(&"#[cfg(test)]") {
            continue;
        }
        match attrs.iter().find_map(|a| a.strip_prefix("#[path = \"").and_then(|a| a.strip_suffix("\"]"))) {
            Some(path) => out.push(rel.parent().unwrap_or(Path::new("")).join(path)),
            None => {
                out.push(dir.join(format!("{name}.rs")));
                out.push(dir.join(name).join("mod.rs"));
            }
        }
    }
    out
}

/// The code of a file without its test module and its comments.
fn code(text: &str) -> String {
    let mut kept = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        if line.trim() == "#[cfg(test)]" && lines.get(i + 1).is_some_and(|l| l.trim_start().starts_with("mod tests")) {
            break;
        }
        kept.push(line.split("//").next().unwrap_or(""));
    }
    kept.join("\n")
}

/// The module paths `code` names: `crate::a::b` as is, `super::x` from `module`'s parent.
fn paths(module: &str, code: &str) -> Vec<Vec<String>> {
    let mut parent: Vec<String> = module.split("::").map(str::to_owned).collect();
    parent.pop();
    let mut out = Vec::new();
    for (prefix, base) in [("crate::", Vec::new()), ("super::", parent)] {
        let mut rest = code;
        while let Some(i) = rest.find(prefix) {
            let before = rest[..i].chars().next_back();
            rest = &rest[i + prefix.len()..];
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let mut p = base.clone();
            let mut tail = rest;
            while let Some(t) = tail.strip_prefix("super::") {
                p.pop();
                tail = t;
            }
            rest = tail;
            for seg in tail.split("::") {
                let ident: String = seg.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if ident.is_empty() {
                    break;
                }
                let whole = ident.len() == seg.len();
                p.push(ident);
                if !whole {
                    break;
                }
            }
            out.push(p);
        }
    }
    out
}

/// The import graph between module files, test code left out.
fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let texts: Vec<(PathBuf, String)> = files
        .iter()
        .map(|f| (f.strip_prefix(&src).unwrap().to_path_buf(), std::fs::read_to_string(f).expect("readable")))
        .collect();
    let test_only: BTreeSet<PathBuf> = texts.iter().flat_map(|(rel, text)| test_only_files(rel, text)).collect();
    let modules: BTreeSet<String> = texts.iter().map(|(rel, _)| module_of(rel)).collect();
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (rel, text) in &texts {
        let module = module_of(rel);
        if test_only.contains(rel) || module == "lib" || module == "main" {
            continue;
        }
        let edges = g.entry(module.clone()).or_default();
        for p in paths(&module, &code(text)) {
            // The longest prefix that is a module file.
            let Some(target) = (1..=p.len()).rev().map(|k| p[..k].join("::")).find(|m| modules.contains(m)) else {
                continue;
            };
            // A module's own children and ancestors are its own rooms.
            if target != module && !module.starts_with(&format!("{target}::")) {
                edges.insert(target);
            }
        }
    }
    g
}

fn top(module: &str) -> &str {
    module.split("::").next().unwrap_or(module)
}

#[test]
fn every_import_points_down_the_layers() {
    let g = graph();
    let rank = |m: &str| LAYERS.iter().position(|l| *l == top(m));
    let mut wrong = Vec::new();
    for (from, tos) in &g {
        let Some(rf) = rank(from) else {
            wrong.push(format!("{from}: top-level module not in LAYERS"));
            continue;
        };
        for to in tos {
            let Some(rt) = rank(to) else { continue };
            if rt > rf {
                wrong.push(format!("{from} -> {to} ({} is above {})", top(to), top(from)));
            }
        }
    }
    assert!(wrong.is_empty(), "imports against the layering:\n{}", wrong.join("\n"));
}

#[test]
fn no_module_reaches_itself_through_others() {
    let g = graph();
    // Tarjan's strongly connected components; any with two or more files is a cycle.
    struct T<'a> {
        g: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        cycles: Vec<Vec<&'a str>>,
    }
    impl<'a> T<'a> {
        fn visit(&mut self, v: &'a str) {
            let n = self.index.len();
            self.index.insert(v, n);
            self.low.insert(v, n);
            self.stack.push(v);
            for w in self.g.get(v).into_iter().flatten() {
                if !self.index.contains_key(w.as_str()) {
                    self.visit(w);
                    let lw = self.low[w.as_str()];
                    let lv = self.low.get_mut(v).unwrap();
                    *lv = (*lv).min(lw);
                } else if self.stack.contains(&w.as_str()) {
                    let iw = self.index[w.as_str()];
                    let lv = self.low.get_mut(v).unwrap();
                    *lv = (*lv).min(iw);
                }
            }
            if self.low[v] == self.index[v] {
                let mut comp = Vec::new();
                while let Some(w) = self.stack.pop() {
                    comp.push(w);
                    if w == v {
                        break;
                    }
                }
                if comp.len() > 1 {
                    comp.sort();
                    self.cycles.push(comp);
                }
            }
        }
    }
    let mut t = T { g: &g, index: BTreeMap::new(), low: BTreeMap::new(), stack: Vec::new(), cycles: Vec::new() };
    for v in g.keys() {
        if !t.index.contains_key(v.as_str()) {
            t.visit(v);
        }
    }
    let cycles = &t.cycles;
    assert!(cycles.is_empty(), "import cycles: {cycles:#?}");
}

/// The reader itself: a path is resolved to its longest module prefix, comments and test
/// modules do not count, and `super::` climbs from the file's parent.
#[test]
fn the_reader_sees_imports_and_only_imports() {
    let text = "use crate::a::b::C;\n// use crate::z::Q;\nfn f() { super::sib::g(); }\n#[cfg(test)]\nmod tests {\n use crate::t::U;\n}\n";
    let p = paths("m::n", &code(text));
    assert_eq!(p, vec![vec!["a", "b", "C"], vec!["m", "sib", "g"]]);
    let p = paths("m::n", "super::super::x::Y");
    assert_eq!(p, vec![vec!["x", "Y"]]);
    assert_eq!(module_of(Path::new("a/b/mod.rs")), "a::b");
    assert_eq!(
        test_only_files(Path::new("a/mod.rs"), "#[cfg(test)]\nmod v;\n"),
        vec![PathBuf::from("a/v.rs"), PathBuf::from("a/v/mod.rs")]
    );
}
