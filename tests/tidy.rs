//! Tidy checks on the source, as rust-analyzer's tidy tests keep theirs: no function over
//! `MAX_LINES` lines in the service's and the verbs' code (`daemon/`, `cli/`, `diagnose/`,
//! `estimate/`, the session core and the pipeline), outside test code. There is no list of
//! exceptions.

use std::path::{Path, PathBuf};

/// The longest a function may be, lines from its `fn` to its closing brace.
const MAX_LINES: usize = 80;

/// Where the limit holds, under `src/`.
const CHECKED: [&str; 6] = ["daemon", "cli", "diagnose", "estimate", "session.rs", "pipeline.rs"];

fn rust_files(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_file() {
        out.push(path.to_path_buf());
        return;
    }
    for entry in std::fs::read_dir(path).expect("readable") {
        let p = entry.expect("an entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// Each function of `text` (before its test module) with its length in lines: from the
/// line of `fn` to the closing brace at the same indentation.
fn functions(text: &str) -> Vec<(String, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let end = (0..lines.len())
        .find(|&i| {
            lines[i].trim() == "#[cfg(test)]"
                && lines.get(i + 1).is_some_and(|l| l.trim_start().starts_with("mod tests"))
        })
        .unwrap_or(lines.len());
    let mut out = Vec::new();
    for i in 0..end {
        let line = lines[i];
        let code = line.trim_start();
        let indent = line.len() - code.len();
        let after_vis = ["pub(crate) ", "pub(super) ", "pub "].iter().fold(code, |c, v| c.strip_prefix(v).unwrap_or(c));
        let after_async = after_vis.strip_prefix("async ").unwrap_or(after_vis);
        let Some(rest) = after_async.strip_prefix("fn ") else { continue };
        let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        // Its body opens on the first line ending in `{` (a declaration ends in `;`).
        let Some(open) = (i..end).find(|&j| lines[j].trim_end().ends_with('{') || lines[j].trim_end().ends_with(';'))
        else {
            continue;
        };
        if lines[open].trim_end().ends_with(';') {
            continue;
        }
        let close = (open + 1..end)
            .find(|&k| {
                let l = lines[k];
                l.len() > indent && l[..indent].trim().is_empty() && l[indent..].starts_with('}')
            })
            .unwrap_or(end);
        out.push((name, close - i + 1));
    }
    out
}

#[test]
fn no_function_in_the_service_and_the_verbs_is_over_80_lines() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    for c in CHECKED {
        rust_files(&src.join(c), &mut files);
    }
    // Files declared under `#[cfg(test)]` (`mod rates;` after it) are test code.
    let test_only = |f: &Path| {
        let Some(stem) = f.file_stem().and_then(|s| s.to_str()) else { return false };
        let parent = f.parent().map(|d| d.join("mod.rs")).filter(|m| m.is_file());
        parent.and_then(|m| std::fs::read_to_string(m).ok()).is_some_and(|t| {
            let lines: Vec<&str> = t.lines().map(str::trim).collect();
            lines.windows(2).any(|w| w[0] == "#[cfg(test)]" && w[1] == format!("mod {stem};"))
        })
    };
    let mut long = Vec::new();
    for f in files.iter().filter(|f| !test_only(f)) {
        let rel = f.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
        for (name, n) in functions(&std::fs::read_to_string(f).unwrap()) {
            if n > MAX_LINES {
                long.push((format!("{rel}:{name}"), n));
            }
        }
    }
    let wrong: Vec<String> = long.iter().map(|(f, n)| format!("{f} is {n} lines (at most {MAX_LINES})")).collect();
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// The reader: a function's lines run from `fn` to the brace that closes it at its indent.
#[test]
fn the_reader_measures_a_function_from_fn_to_its_brace() {
    let text = "fn a() {\n    if x {\n    }\n}\n    pub(crate) async fn b(\n        y: u8,\n    ) -> u8 {\n        y\n    }\nfn c();\n#[cfg(test)]\nmod tests {\nfn d() {\n}\n}\n";
    assert_eq!(functions(text), vec![("a".to_string(), 4), ("b".to_string(), 5)]);
}
