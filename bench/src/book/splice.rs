//! Splicing tables into a book page. A block is the lines between a `<!-- bench:NAME -->` line
//! and its `<!-- /bench:NAME -->` line; splicing replaces what a block holds and keeps every byte
//! outside the blocks. Markers are HTML comments, so the rendered book does not show them. A
//! page whose markers do not pair up is refused as a whole: nothing is half-written.
//!
//! A leaf (no I/O, nothing else of the crate): the chapter test (`bench/tests/book.rs`) includes
//! this file to read the page exactly as `--book` does.

use std::fmt;
use std::ops::Range;

/// A block of a page: its name, the line of its opening marker (1-based) and the bytes it holds
/// (from the line after the opening marker to the start of the closing one).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block<'a> {
    pub name: &'a str,
    pub line: usize,
    content: Range<usize>,
}

/// Why a page's markers cannot be spliced. Lines are 1-based.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Error {
    /// A line that starts like a marker but is not one.
    Malformed { line: usize },
    /// A block whose name is not one of the bench's tables.
    Unknown { line: usize, name: String },
    /// A block opened inside another.
    Nested {
        line: usize,
        name: String,
        outer: String,
        outer_line: usize,
    },
    /// A closing marker with no block open.
    Unopened { line: usize, name: String },
    /// A closing marker for another block than the open one.
    Mismatched {
        line: usize,
        name: String,
        open: String,
        open_line: usize,
    },
    /// A block that is never closed.
    Unclosed { line: usize, name: String },
    /// A second block of the same name.
    Duplicate {
        line: usize,
        name: String,
        first_line: usize,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Malformed { line } => write!(
                f,
                "line {line}: a marker is `<!-- bench:NAME -->` or `<!-- /bench:NAME -->` alone on its line, NAME of a-z, 0-9 and -"
            ),
            Error::Unknown { line, name } => {
                write!(f, "line {line}: the bench writes no table named `{name}`")
            }
            Error::Nested {
                line,
                name,
                outer,
                outer_line,
            } => write!(
                f,
                "line {line}: block `{name}` opens inside block `{outer}` (line {outer_line}); blocks do not nest"
            ),
            Error::Unopened { line, name } => write!(
                f,
                "line {line}: `<!-- /bench:{name} -->` closes a block that is not open"
            ),
            Error::Mismatched {
                line,
                name,
                open,
                open_line,
            } => write!(
                f,
                "line {line}: `<!-- /bench:{name} -->` inside block `{open}` (line {open_line}), which it does not close"
            ),
            Error::Unclosed { line, name } => write!(
                f,
                "line {line}: block `{name}` is never closed (`<!-- /bench:{name} -->`)"
            ),
            Error::Duplicate {
                line,
                name,
                first_line,
            } => write!(
                f,
                "line {line}: a second block `{name}` (the first is at line {first_line})"
            ),
        }
    }
}

impl std::error::Error for Error {}

enum Marker<'a> {
    Open(&'a str),
    Close(&'a str),
}

/// The marker a line is, if it is one. A line is a marker attempt when it starts with `<!--`
/// followed by `bench:` or `/bench:`; a mention inside a sentence is prose.
fn marker(line: &str) -> Result<Option<Marker<'_>>, ()> {
    let Some(rest) = line.trim().strip_prefix("<!--") else {
        return Ok(None);
    };
    let rest = rest.trim_start();
    let (close, rest) = match rest.strip_prefix("/bench:") {
        Some(r) => (true, r),
        None => match rest.strip_prefix("bench:") {
            Some(r) => (false, r),
            None => return Ok(None),
        },
    };
    let name = rest.strip_suffix("-->").ok_or(())?.trim();
    let valid = !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-');
    match (valid, close) {
        (false, _) => Err(()),
        (true, false) => Ok(Some(Marker::Open(name))),
        (true, true) => Ok(Some(Marker::Close(name))),
    }
}

/// The page's blocks, in order, once every marker pairs up. Markers inside fenced code
/// (``` or ~~~) are text, not markers.
pub fn blocks(text: &str) -> Result<Vec<Block<'_>>, Error> {
    let mut out: Vec<Block> = Vec::new();
    let mut open: Option<(&str, usize, usize)> = None; // name, line, content start
    let mut fenced = false;
    let mut at = 0;
    for (i, l) in text.split_inclusive('\n').enumerate() {
        let (line, start) = (i + 1, at);
        at += l.len();
        let t = l.trim_start();
        if t.starts_with("```") || t.starts_with("~~~") {
            fenced = !fenced;
        }
        if fenced {
            continue;
        }
        match marker(l).map_err(|()| Error::Malformed { line })? {
            None => {}
            Some(Marker::Open(name)) => {
                if let Some((outer, outer_line, _)) = open {
                    return Err(Error::Nested {
                        line,
                        name: name.into(),
                        outer: outer.into(),
                        outer_line,
                    });
                }
                if let Some(b) = out.iter().find(|b| b.name == name) {
                    return Err(Error::Duplicate {
                        line,
                        name: name.into(),
                        first_line: b.line,
                    });
                }
                open = Some((name, line, at));
            }
            Some(Marker::Close(name)) => match open.take() {
                None => {
                    return Err(Error::Unopened {
                        line,
                        name: name.into(),
                    })
                }
                Some((o, open_line, _)) if o != name => {
                    return Err(Error::Mismatched {
                        line,
                        name: name.into(),
                        open: o.into(),
                        open_line,
                    })
                }
                Some((_, open_line, from)) => out.push(Block {
                    name,
                    line: open_line,
                    content: from..start,
                }),
            },
        }
    }
    match open {
        Some((name, line, _)) => Err(Error::Unclosed {
            line,
            name: name.into(),
        }),
        None => Ok(out),
    }
}

/// [`blocks`], and every block names a table for which `known` is true.
pub fn check<'a>(text: &'a str, known: &dyn Fn(&str) -> bool) -> Result<Vec<Block<'a>>, Error> {
    let b = blocks(text)?;
    match b.iter().find(|b| !known(b.name)) {
        Some(u) => Err(Error::Unknown {
            line: u.line,
            name: u.name.into(),
        }),
        None => Ok(b),
    }
}

/// The page with each block named in `tables` (name, markdown) holding that markdown between
/// blank lines, the other blocks and everything outside them unchanged, and the names written.
pub fn splice(
    text: &str,
    tables: &[(&str, &str)],
    known: &dyn Fn(&str) -> bool,
) -> Result<(String, Vec<String>), Error> {
    let mut out = String::with_capacity(text.len());
    let mut written = Vec::new();
    let mut kept_to = 0;
    for b in check(text, known)? {
        let Some((_, md)) = tables.iter().find(|(n, _)| *n == b.name) else {
            continue;
        };
        out.push_str(&text[kept_to..b.content.start]);
        out.push('\n');
        out.push_str(md.trim_matches(|c: char| c.is_whitespace()));
        out.push_str("\n\n");
        kept_to = b.content.end;
        written.push(b.name.to_string());
    }
    out.push_str(&text[kept_to..]);
    Ok((out, written))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn known(n: &str) -> bool {
        ["latency", "jitter", "e2e"].contains(&n)
    }

    const PAGE: &str = "# Perf\n\nProse before.\n\n<!-- bench:latency -->\n\nold latency\n\n| a |\n|---|\n| 1 |\n\n<!-- /bench:latency -->\n\nProse between, `<!-- bench:nothing -->` in a sentence.\n\n```md\n<!-- bench:example -->\n```\n\n<!-- bench:jitter -->\nold jitter\n<!-- /bench:jitter -->\nProse after.\n";

    #[test]
    fn replaces_the_named_blocks_and_keeps_the_prose() {
        let (out, written) = splice(
            PAGE,
            &[("latency", "Run: now\n\n| b |\n|---|\n| 2 |\n")],
            &known,
        )
        .unwrap();
        assert_eq!(written, ["latency"]);
        assert_eq!(
            out,
            PAGE.replace(
                "\nold latency\n\n| a |\n|---|\n| 1 |\n\n",
                "\nRun: now\n\n| b |\n|---|\n| 2 |\n\n"
            )
        );
        assert!(out.contains("Prose before.\n\n<!-- bench:latency -->\n\nRun: now"));
        assert!(out.ends_with(
            "<!-- bench:jitter -->\nold jitter\n<!-- /bench:jitter -->\nProse after.\n"
        ));
    }

    #[test]
    fn a_part_not_run_leaves_its_block_and_a_table_without_a_block_is_not_written() {
        let (out, written) = splice(PAGE, &[], &known).unwrap();
        assert_eq!((out.as_str(), written.len()), (PAGE, 0));
        let (out, written) = splice(PAGE, &[("e2e", "| e |\n")], &known).unwrap();
        assert_eq!((out.as_str(), written.len()), (PAGE, 0));
        let (out, written) =
            splice(PAGE, &[("jitter", "new jitter"), ("e2e", "| e |")], &known).unwrap();
        assert_eq!(written, ["jitter"]);
        assert!(out.contains(
            "<!-- bench:jitter -->\n\nnew jitter\n\n<!-- /bench:jitter -->\nProse after.\n"
        ));
        assert!(out.contains("old latency"));
    }

    #[test]
    fn splicing_twice_gives_the_same_page() {
        let t = [
            ("latency", "\n\nRun: x\n\n| b |\n|---|\n"),
            ("jitter", "| j |\n|---|"),
        ];
        let (once, _) = splice(PAGE, &t, &known).unwrap();
        let (twice, _) = splice(&once, &t, &known).unwrap();
        assert_eq!(once, twice);
        let (none, _) = splice(&once, &[], &known).unwrap();
        assert_eq!(none, once);
    }

    #[test]
    fn markers_that_do_not_pair_up_are_refused_with_their_line() {
        let cases: [(&str, Error); 7] = [
            (
                "a\n<!-- bench:latency -->\nx\n",
                Error::Unclosed { line: 2, name: "latency".into() },
            ),
            (
                "<!-- /bench:latency -->\n",
                Error::Unopened { line: 1, name: "latency".into() },
            ),
            (
                "<!-- bench:latency -->\n<!-- bench:jitter -->\n<!-- /bench:jitter -->\n<!-- /bench:latency -->\n",
                Error::Nested {
                    line: 2,
                    name: "jitter".into(),
                    outer: "latency".into(),
                    outer_line: 1,
                },
            ),
            (
                "<!-- bench:latency -->\n<!-- /bench:jitter -->\n",
                Error::Mismatched {
                    line: 2,
                    name: "jitter".into(),
                    open: "latency".into(),
                    open_line: 1,
                },
            ),
            (
                "<!-- bench:e2e -->\n<!-- /bench:e2e -->\n\n<!-- bench:e2e -->\n<!-- /bench:e2e -->\n",
                Error::Duplicate { line: 4, name: "e2e".into(), first_line: 1 },
            ),
            ("x\n\n<!-- bench:Latency -->\n", Error::Malformed { line: 3 }),
            ("<!-- bench:latency\n", Error::Malformed { line: 1 }),
        ];
        for (page, want) in cases {
            let got = splice(page, &[("latency", "t")], &known).unwrap_err();
            assert_eq!(got, want, "{page:?}");
            assert!(got.to_string().starts_with(&format!(
                "line {}",
                match want {
                    Error::Malformed { line }
                    | Error::Unknown { line, .. }
                    | Error::Nested { line, .. }
                    | Error::Unopened { line, .. }
                    | Error::Mismatched { line, .. }
                    | Error::Unclosed { line, .. }
                    | Error::Duplicate { line, .. } => line,
                }
            )));
        }
    }

    #[test]
    fn an_unknown_name_is_refused_and_blocks_are_read_in_order() {
        let page = "<!-- bench:e2e -->\n<!-- /bench:e2e -->\n<!-- bench:e2e-old -->\n<!-- /bench:e2e-old -->\n";
        assert_eq!(
            check(page, &known).unwrap_err(),
            Error::Unknown {
                line: 3,
                name: "e2e-old".into()
            }
        );
        let b = blocks(PAGE).unwrap();
        assert_eq!(
            b.iter().map(|b| (b.name, b.line)).collect::<Vec<_>>(),
            [("latency", 5), ("jitter", 21)]
        );
    }
}
