//! `control` is a stack of layers, and this test keeps it one.
//!
//! Every top-level module of `control` sits on a declared floor ([`FLOORS`], bottom first). A
//! module may use what sits on its own floor or below, never what sits above, and no two
//! modules may use each other round a circle, on one floor or across several. The test reads
//! the sources as text: every `crate::x`, `$crate::x` and `use crate::{x, …}` in code outside
//! `#[cfg(test)]` blocks is an import of module `x` (a crate-root name is followed to the
//! module that defines or re-exports it). It also checks that no module reads a clock: timing a
//! computation is the caller's business, so the same call is bit-identical wherever it runs.
//! And it checks that no public seam of `control`, `protocol` or `rt` answers with a bare
//! `String` for an error.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The floors, bottom first. Adding a module means giving it a floor here.
const FLOORS: &[(&str, &[&str])] = &[
    (
        "ground: joint counts, flags, errors, angles, small algebra",
        &["basics", "dual"],
    ),
    (
        "models: the planar closed form, URDF chains, the delay line",
        &["arm", "model", "delay"],
    ),
    ("tasks: paths and their errors", &["task"]),
    ("secondary tasks", &["secondary"]),
    ("safety rows and the filter", &["safety"]),
    ("command interfaces and limits", &["command"]),
    (
        "steering references: planned cycles as the law reads them",
        &["steer"],
    ),
    ("the law's joint-space core", &["resolve"]),
    ("the adaptive gain", &["adapt"]),
    ("the control law", &["law"]),
    ("simulation", &["sim"]),
    ("the tick's law for any arm", &["tick_law"]),
    ("the sampled-data hold", &["hold"]),
    ("the rigid-body plant", &["rigid_body"]),
    ("chaos analysis", &["analysis"]),
    (
        "configuration, its validation and the sampled loop's limits",
        &["config"],
    ),
    ("the whole set-up: either arm from one file", &["system"]),
    (
        "monitor, planner and the gain from the model",
        &["monitor", "plan", "target", "tune"],
    ),
    ("the loop through a command interface", &["commanded"]),
];

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level module a file belongs to (`plan/spatial/mod.rs` → `plan`); None for lib.rs.
fn module_of(path: &Path) -> Option<String> {
    let rel = path.strip_prefix(src_dir()).unwrap();
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    match first.strip_suffix(".rs") {
        Some("lib") => None,
        Some(m) => Some(m.to_string()),
        None => Some(first),
    }
}

/// The code of a file without its test modules and comments.
fn code(text: &str) -> String {
    let mut out = String::new();
    let mut skip_depth: Option<i32> = None;
    let mut depth = 0i32;
    for line in text.lines() {
        let trimmed = line.trim_start();
        if skip_depth.is_none() && trimmed.starts_with("#[cfg(test)]") {
            skip_depth = Some(depth);
            continue;
        }
        let opens = line.matches('{').count() as i32;
        let closes = line.matches('}').count() as i32;
        depth += opens - closes;
        if let Some(d) = skip_depth {
            // The item after the attribute ends where the depth comes back to where it was.
            if depth <= d && (closes > 0 || line.trim_end().ends_with(';')) {
                skip_depth = None;
            }
            continue;
        }
        if trimmed.starts_with("//") {
            continue;
        }
        let code = line.split("//").next().unwrap_or("");
        out.push_str(code);
        out.push('\n');
    }
    out
}

fn ident_at(s: &str) -> &str {
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// Every first path segment after `crate::` (and inside `crate::{…}` groups).
fn imported_names(code: &str) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let mut level = 0;
            let mut start = true;
            for (k, c) in group.char_indices() {
                match c {
                    '{' => level += 1,
                    '}' if level == 0 => break,
                    '}' => level -= 1,
                    ',' if level == 0 => start = true,
                    c if start && level == 0 && (c.is_alphanumeric() || c == '_') => {
                        names.insert(ident_at(&group[k..]).to_string());
                        start = false;
                    }
                    _ => {}
                }
            }
        } else {
            let name = ident_at(rest);
            if !name.is_empty() {
                names.insert(name.to_string());
            }
        }
    }
    names
}

/// Crate-root names (re-exports in lib.rs, exported macros) and the module each comes from.
fn root_names(files: &[PathBuf]) -> BTreeMap<String, String> {
    let mut map = BTreeMap::new();
    let lib = std::fs::read_to_string(src_dir().join("lib.rs")).unwrap();
    for line in lib.lines() {
        let Some(rest) = line.trim().strip_prefix("pub use ") else {
            continue;
        };
        let module = ident_at(rest).to_string();
        let items = rest.split_once('{').map_or(rest, |(_, r)| r);
        for item in items.split([',', ':', '}', ';']) {
            let item = item.trim();
            if !item.is_empty() && item != module {
                map.insert(item.to_string(), module.clone());
            }
        }
    }
    for file in files {
        let Some(module) = module_of(file) else {
            continue;
        };
        let text = std::fs::read_to_string(file).unwrap();
        for (i, _) in text.match_indices("macro_rules! ") {
            let name = ident_at(&text[i + "macro_rules! ".len()..]);
            map.insert(name.to_string(), module.clone());
        }
    }
    map
}

struct Graph {
    edges: BTreeMap<String, BTreeMap<String, Vec<String>>>,
}

fn graph() -> Graph {
    let mut files = Vec::new();
    rust_files(&src_dir(), &mut files);
    files.sort();
    let roots = root_names(&files);
    let mut edges: BTreeMap<String, BTreeMap<String, Vec<String>>> = BTreeMap::new();
    for file in &files {
        let Some(from) = module_of(file) else {
            continue;
        };
        let text = code(&std::fs::read_to_string(file).unwrap());
        let rel = file.strip_prefix(src_dir()).unwrap().display().to_string();
        for name in imported_names(&text) {
            let to = roots.get(&name).cloned().unwrap_or(name);
            if to != from && to != "self" {
                edges
                    .entry(from.clone())
                    .or_default()
                    .entry(to)
                    .or_default()
                    .push(rel.clone());
            }
        }
    }
    Graph { edges }
}

fn floor_of(module: &str) -> Option<usize> {
    FLOORS.iter().position(|(_, ms)| ms.contains(&module))
}

#[test]
fn every_module_has_a_floor() {
    let mut files = Vec::new();
    rust_files(&src_dir(), &mut files);
    let missing: BTreeSet<String> = files
        .iter()
        .filter_map(|f| module_of(f))
        .filter(|m| floor_of(m).is_none())
        .collect();
    assert!(
        missing.is_empty(),
        "modules of control without a floor in FLOORS: {missing:?}"
    );
}

#[test]
fn every_import_runs_down() {
    let g = graph();
    let mut upward = Vec::new();
    for (from, tos) in &g.edges {
        let Some(f) = floor_of(from) else { continue };
        for (to, files) in tos {
            match floor_of(to) {
                Some(t) if t > f => upward.push(format!(
                    "{from} ({}) imports {to} ({}) in {}",
                    FLOORS[f].0,
                    FLOORS[t].0,
                    files.join(", ")
                )),
                Some(_) => {}
                None => upward.push(format!("{from} imports {to}, which is no module")),
            }
        }
    }
    assert!(
        upward.is_empty(),
        "imports that run up:\n{}",
        upward.join("\n")
    );
}

#[test]
fn no_import_circles() {
    let g = graph();
    // Depth-first search with colours: grey marks the modules on the current path.
    fn visit<'a>(
        m: &'a str,
        g: &'a Graph,
        colour: &mut BTreeMap<&'a str, u8>,
        path: &mut Vec<&'a str>,
        found: &mut Vec<String>,
    ) {
        colour.insert(m, 1);
        path.push(m);
        for to in g.edges.get(m).into_iter().flat_map(|t| t.keys()) {
            match colour.get(to.as_str()) {
                Some(1) => {
                    let start = path.iter().position(|p| p == to).unwrap();
                    found.push(format!("{} → {to}", path[start..].join(" → ")));
                }
                Some(_) => {}
                None => visit(to, g, colour, path, found),
            }
        }
        path.pop();
        colour.insert(m, 2);
    }
    let mut colour = BTreeMap::new();
    let mut found = Vec::new();
    for m in g.edges.keys() {
        if !colour.contains_key(m.as_str()) {
            visit(m, &g, &mut colour, &mut Vec::new(), &mut found);
        }
    }
    assert!(found.is_empty(), "import circles:\n{}", found.join("\n"));
}

#[test]
fn no_module_reads_a_clock() {
    let mut files = Vec::new();
    rust_files(&src_dir(), &mut files);
    let readers: Vec<String> = files
        .iter()
        .filter(|f| {
            let text = code(&std::fs::read_to_string(f).unwrap());
            ["Instant::now", "SystemTime", "std::time::Instant"]
                .iter()
                .any(|clock| text.contains(clock))
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(readers.is_empty(), "control reads a clock in {readers:?}");
}

#[test]
fn the_checker_sees_what_it_should() {
    let text = "use crate::{a::B, c};\nfn f() { crate::d::e(); $crate::g::h }\n// crate::x\n#[cfg(test)]\nmod tests {\n    use crate::y;\n}\n";
    let names = imported_names(&code(text));
    let expected: BTreeSet<String> = ["a", "c", "d", "g"].map(String::from).into();
    assert_eq!(names, expected);
}

/// Every `Result<…, String>` written in `code` (white space and a trailing comma aside, as
/// rustfmt splits a long one over lines): from `Result<` to the `String>` that closes it, when
/// no `;`, `{` or `}` falls between (one signature or type).
fn string_results(code: &str) -> Vec<String> {
    let compact: String = code
        .split_whitespace()
        .collect::<String>()
        .replace(",>", ">");
    let mut found = Vec::new();
    for (i, _) in compact.match_indices(",String>") {
        let Some(start) = compact[..i].rfind("Result<") else {
            continue;
        };
        if !compact[start..i].contains([';', '{', '}']) {
            found.push(compact[start..i + ",String>".len()].to_string());
        }
    }
    found
}

/// The public seams of `control`, `protocol` and `rt` give typed errors: a caller can match on
/// what went wrong, and only the outermost layer (the daemon's answer, the client's message)
/// turns one into text.
#[test]
fn no_string_errors_at_the_seams() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut offenders = Vec::new();
    for krate in ["control", "protocol", "rt"] {
        let mut files = Vec::new();
        rust_files(&root.join(krate).join("src"), &mut files);
        for f in files {
            for hit in string_results(&code(&std::fs::read_to_string(&f).unwrap())) {
                offenders.push(format!("{}: {hit}", f.display()));
            }
        }
    }
    assert!(
        offenders.is_empty(),
        "Result<_, String> outside tests:\n{}",
        offenders.join("\n")
    );
}

#[test]
fn the_string_result_check_sees_what_it_should() {
    let text = "pub fn a() -> Result<u8, String> {}\nfn b() -> Result<\n    Vec<u8>,\n    String,\n> {}\nfn c() -> Result<(), Error> { let s: Vec<String> = v; }\n";
    let hits = string_results(&code(text));
    assert_eq!(
        hits,
        ["Result<u8,String>", "Result<Vec<u8>,String>"],
        "{hits:?}"
    );
}
