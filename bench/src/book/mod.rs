//! The bench's tables in the book. With `--book PATH`, each table a run produced goes into the
//! page's block of the same name (`splice`), under a line that says when, on what and how it was
//! run, so the book's numbers are the bench's own and never pasted by hand. Names are
//! `names`'s; a part that did not run leaves its blocks as they are, and a page whose markers are
//! wrong is refused before the run starts and is never half-written.

pub mod names;
pub mod splice;
pub mod table;

use anyhow::{anyhow, Context, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use table::Table;

/// The command a run line quotes: the arguments as given, less `--out` and `--book` (where the
/// files went changes no number).
pub fn command(args: &[String]) -> String {
    let mut kept = vec!["chaosd-bench"];
    let mut skip = false;
    for a in args {
        if std::mem::take(&mut skip) {
            continue;
        }
        match a.as_str() {
            "--out" | "--book" => skip = true,
            _ if a.starts_with("--out=") || a.starts_with("--book=") => {}
            _ => kept.push(a),
        }
    }
    kept.join(" ")
}

/// The page `--book` names, and the command its run lines quote.
pub struct Book {
    pub path: PathBuf,
    pub command: String,
}

impl Book {
    fn read(&self) -> Result<String> {
        std::fs::read_to_string(&self.path)
            .with_context(|| format!("--book: cannot read {}", self.path.display()))
    }

    fn refused(&self, e: splice::Error) -> anyhow::Error {
        let hint = match e {
            splice::Error::Unknown { .. } => {
                let all: Vec<&str> = names::ALL.iter().map(|t| t.name).collect();
                format!(" (its tables: {})", all.join(", "))
            }
            _ => String::new(),
        };
        anyhow!("--book {}: {e}{hint}; not written", self.path.display())
    }

    /// Reads and checks the page before a run, so a bad marker costs a second, not the run;
    /// returns the blocks missing from a page of the book that should carry them.
    pub fn check(&self) -> Result<Vec<&'static str>> {
        let text = self.read()?;
        let blocks = splice::check(&text, &names::known).map_err(|e| self.refused(e))?;
        let page = self.path.file_name().map(|n| n.to_string_lossy());
        Ok(page.map_or_else(Vec::new, |page| {
            names::carried_by(&page)
                .map(|t| t.name)
                .filter(|n| !blocks.iter().any(|b| b.name == *n))
                .collect()
        }))
    }

    /// Writes `tables` into their blocks of the page (a temporary file renamed over it) and says
    /// in one line what was written and what had no block.
    pub fn write(&self, tables: &[Table]) -> Result<String> {
        let text = self.read()?;
        let machine = crate::report::machine();
        let blocks: Vec<String> = tables
            .iter()
            .map(|t| t.block(&machine, &self.command))
            .collect();
        let pairs: Vec<(&str, &str)> = tables
            .iter()
            .zip(&blocks)
            .map(|(t, b)| (t.name, b.as_str()))
            .collect();
        let (new, written) =
            splice::splice(&text, &pairs, &names::known).map_err(|e| self.refused(e))?;
        let missing: Vec<&str> = tables
            .iter()
            .map(|t| t.name)
            .filter(|n| !written.iter().any(|w| w == n))
            .collect();
        if new != text {
            write_atomically(&self.path, &new)?;
        }
        let mut line = if written.is_empty() {
            format!(
                "{}: no block for this run's tables; left as it was",
                self.path.display()
            )
        } else {
            format!("{}: wrote {}", self.path.display(), written.join(", "))
        };
        if !written.is_empty() && !missing.is_empty() {
            line.push_str(&format!("; no block for {}", missing.join(", ")));
        }
        Ok(line)
    }
}

/// Replaces `path` with `text` all at once: written to a temporary file beside it (its
/// permissions copied), synced, then renamed over it. A symlink's target is replaced, not the link.
fn write_atomically(path: &Path, text: &str) -> Result<()> {
    let path = std::fs::canonicalize(path)
        .with_context(|| format!("--book: cannot resolve {}", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new("/"));
    let name = path
        .file_name()
        .map_or_else(|| "book".into(), |n| n.to_string_lossy());
    let tmp = dir.join(format!(".{name}.chaosd-bench-{}", std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.set_permissions(std::fs::metadata(&path)?.permissions())?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("--book: cannot write {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(name: &'static str, markdown: &str) -> Table {
        Table {
            name,
            date: "2026-01-02 03:04 UTC".into(),
            detail: Some("3 rounds".into()),
            markdown: markdown.into(),
        }
    }

    #[test]
    fn the_run_line_quotes_the_command_without_its_paths() {
        let args: Vec<String> = [
            "--quick",
            "--out",
            "/tmp/o",
            "all",
            "--book=/tmp/p.md",
            "--priority",
            "40",
        ]
        .map(String::from)
        .into();
        assert_eq!(command(&args), "chaosd-bench --quick all --priority 40");
        assert_eq!(
            table("latency", "| a |\n|---|\n").block("2 vCPU", "chaosd-bench all"),
            "Run: 2026-01-02 03:04 UTC on 2 vCPU; 3 rounds; `chaosd-bench all`.\n\n| a |\n|---|"
        );
    }

    #[test]
    fn a_page_is_written_whole_or_not_at_all() {
        let dir = std::env::temp_dir().join(format!("chaosd-bench-book-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("page.md");
        let page = "Prose.\n\n<!-- bench:latency -->\nold\n<!-- /bench:latency -->\n\n<!-- bench:jitter -->\nkept\n<!-- /bench:jitter -->\n";
        std::fs::write(&path, page).unwrap();
        let book = Book {
            path: path.clone(),
            command: "chaosd-bench latency".into(),
        };
        assert!(book.check().unwrap().is_empty());
        let said = book
            .write(&[
                table("latency", "| new |\n|---|\n"),
                table("device", "| d |\n"),
            ])
            .unwrap();
        assert!(
            said.ends_with("wrote latency; no block for device"),
            "{said}"
        );
        let once = std::fs::read_to_string(&path).unwrap();
        assert!(once.contains("<!-- bench:latency -->\n\nRun: 2026-01-02 03:04 UTC on "));
        assert!(once.contains(
            "; 3 rounds; `chaosd-bench latency`.\n\n| new |\n|---|\n\n<!-- /bench:latency -->"
        ));
        assert!(once.starts_with("Prose.\n\n") && once.contains("\nkept\n"));
        book.write(&[table("latency", "| new |\n|---|\n")]).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), once);

        let broken = once.replace("<!-- /bench:jitter -->", "");
        std::fs::write(&path, &broken).unwrap();
        let e = book
            .write(&[table("latency", "| newer |\n")])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("block `jitter` is never closed") && e.ends_with("not written"),
            "{e}"
        );
        assert!(book.check().is_err());
        std::fs::write(&path, once.replace("bench:latency", "bench:lat")).unwrap();
        let e = book.check().unwrap_err().to_string();
        assert!(
            e.contains("no table named `lat`") && e.contains("its tables: latency, "),
            "{e}"
        );
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "no temporary file left"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
