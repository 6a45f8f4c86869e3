//! The Panda study's tables in the book (docs/panda-study.md) are what its scripts print today.
//!
//! The scripts make each variant by editing the printed config and judge each run on
//! `chaosctl simulate --json`; when the printed form changed (a new `[feedback] enabled` key, a
//! zero `null_damping` left out), their edits silently did nothing and the book's tables could
//! no longer be made again. Here `scripts/panda-study/run.sh` (its table) and `starts.sh` run
//! against the built binaries, and every row of the book's two tables must be what they print.
//! The scripts read JSON with Python: skipped, saying so, without `CHAOSD_PYTHON`; CI sets it and
//! `CHAOSD_REQUIRE_PYTHON=1`.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The directory whose `python3` the scripts run, or None (the test is skipped).
fn python_dir() -> Option<PathBuf> {
    let Ok(python) = std::env::var("CHAOSD_PYTHON") else {
        assert!(
            std::env::var("CHAOSD_REQUIRE_PYTHON").is_err(),
            "CHAOSD_REQUIRE_PYTHON is set but CHAOSD_PYTHON is not"
        );
        eprintln!("CHAOSD_PYTHON not set: the study scripts not run (CI runs them)");
        return None;
    };
    Some(Path::new(&python).parent().unwrap().to_path_buf())
}

/// Runs `scripts/panda-study/NAME` into a fresh directory; its standard output.
fn script(name: &str, python: &Path, env: &[(&str, &str)]) -> String {
    let out = tests::TempDir::new(&format!("study-{name}-{}", std::process::id()));
    let path = format!(
        "{}:{}",
        python.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let o = Command::new("bash")
        .arg(root().join("scripts/panda-study").join(name))
        .arg(out.path())
        .env("CHAOSD_BIN", tests::bin("chaosctl").parent().unwrap())
        .env("PATH", path)
        .envs(env.iter().copied())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{name}: {}\n{stdout}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

/// A markdown row's cells, trimmed, bold marks dropped.
fn cells(line: &str) -> Vec<String> {
    line.trim()
        .trim_matches('|')
        .split('|')
        .map(|c| c.replace("**", "").trim().to_string())
        .collect()
}

/// The rows of the book's table whose header line is `header` (up to the first non-row line).
fn book_rows(header: &str) -> Vec<Vec<String>> {
    let book = std::fs::read_to_string(root().join("docs/panda-study.md")).unwrap();
    let mut lines = book.lines().skip_while(|l| !l.starts_with(header));
    assert!(lines.next().is_some(), "no table {header:?} in the book");
    lines
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .map(cells)
        .collect()
}

/// The rows of the table a script printed, its header (starting `header`) left out.
fn printed_rows(printed: &str, header: &str) -> Vec<Vec<String>> {
    printed
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with(header))
        .map(cells)
        .collect()
}

/// The first number in a cell (`20`, `1 (\`panda-paper\`)`).
fn number(cell: &str) -> f64 {
    cell.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn the_study_table_is_what_run_sh_prints() {
    let Some(python) = python_dir() else { return };
    let printed = script("run.sh", &python, &[("TABLE_ONLY", "1")]);
    let rows = printed_rows(&printed, "| variant");
    let book = book_rows("| variant | residual before → final");
    assert_eq!(rows.len(), book.len(), "{printed}");
    for (fresh, book) in rows.iter().zip(&book) {
        // The book names a variant and says what it is: `both (centring α = 20 + …)`.
        let name = book[0].split_whitespace().next().unwrap();
        assert_eq!(fresh[0], name, "row order");
        assert_eq!(fresh[1..], book[1..], "variant {name}: script, then book");
    }
}

#[test]
fn the_starts_table_is_what_starts_sh_prints() {
    let Some(python) = python_dir() else { return };
    let printed = script("starts.sh", &python, &[]);
    let rows = printed_rows(&printed, "| α");
    let book = book_rows("| α | k_d | μ | residual ≤ 1e-3 within limits");
    assert_eq!(rows.len(), book.len(), "{printed}");
    for (fresh, book) in rows.iter().zip(&book) {
        for k in 0..3 {
            assert_eq!(number(&fresh[k]), number(&book[k]), "{fresh:?} {book:?}");
        }
        assert_eq!(fresh[3..], book[3..], "script, then book");
    }
}
