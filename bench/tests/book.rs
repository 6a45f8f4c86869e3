//! The book and the bench agree: every block in a book page names a table the bench writes, and
//! every table a page should carry has its block there. The pages are read with the bench's own
//! parser and catalogue (included from `src/book/`), so a renamed table, a mistyped marker or a
//! block lost in an edit fails here, not at the next `chaosd-bench all --book` run.

#[allow(dead_code)]
#[path = "../src/book/names.rs"]
mod names;
#[allow(dead_code)]
#[path = "../src/book/splice.rs"]
mod splice;

use std::path::{Path, PathBuf};

fn docs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs")
}

fn read(page: &str) -> String {
    let p = docs().join(page);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Every page of the book.
fn pages() -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(docs())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".md"))
        .collect();
    v.sort();
    v
}

#[test]
fn every_block_in_the_book_names_a_table_the_bench_writes() {
    for page in pages() {
        let text = read(&page);
        if let Err(e) = splice::check(&text, &names::known) {
            panic!("docs/{page}: {e}; chaosd-bench --book would refuse it");
        }
    }
}

#[test]
fn every_page_carries_the_tables_the_bench_writes_for_it() {
    let mut pages: Vec<&str> = names::ALL.iter().filter_map(|t| t.page).collect();
    pages.sort_unstable();
    pages.dedup();
    assert!(pages.contains(&names::PERFORMANCE));
    for page in pages {
        let text = read(page);
        let blocks = splice::blocks(&text).unwrap_or_else(|e| panic!("docs/{page}: {e}"));
        let missing: Vec<&str> = names::carried_by(page)
            .map(|t| t.name)
            .filter(|n| !blocks.iter().any(|b| b.name == *n))
            .collect();
        assert!(
            missing.is_empty(),
            "docs/{page} has no block for {missing:?} (`<!-- bench:NAME -->` … `<!-- /bench:NAME -->` \
             around the table), or src/book/names.rs names a page that should not carry them"
        );
    }
}

#[test]
fn the_performance_chapter_says_how_its_tables_are_written() {
    let text = read(names::PERFORMANCE);
    assert!(
        text.contains("chaosd-bench all --book docs/performance.md"),
        "docs/performance.md should say near the top how its tables are regenerated"
    );
}
