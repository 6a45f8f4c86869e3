//! The Panda study's tables in the book (docs/panda-study.md) are what its scripts print today.
//!
//! The scripts make each variant by editing the printed config and judge each run on
//! `chaosctl simulate --json`; when the printed form changed (a new `[feedback] enabled` key, a
//! zero `null_damping` left out), their edits silently did nothing and the book's tables could
//! no longer be made again. Here `scripts/panda-study/run.sh` (its table) and `starts.sh` run
//! against the built binaries: every variant must keep the class of motion the book gives it
//! and every start count must hold (to one start); on this machine the rows are the book's to the
//! digit, and a row that differs only in digits (another CPU's libm, in a chaotic run) is named.
//! The scripts read JSON with Python: skipped, saying so, without `CHAOSD_PYTHON`; CI sets it and
//! `CHAOSD_REQUIRE_PYTHON=1`. `basins.sh` runs `chaosctl starts` and needs no Python: its rows of
//! the preset are checked everywhere.

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
    script_with(name, &[], Some(python), env)
}

/// [`script`] with `args` before the output directory, and `python` first on the PATH if given.
fn script_with(name: &str, args: &[&str], python: Option<&Path>, env: &[(&str, &str)]) -> String {
    let out = tests::TempDir::new(&format!("study-{name}-{}", std::process::id()));
    let path = std::env::var("PATH").unwrap_or_default();
    let path = match python {
        Some(p) => format!("{}:{path}", p.display()),
        None => path,
    };
    let o = Command::new("bash")
        .arg(root().join("scripts/panda-study").join(name))
        .args(args)
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

/// What λ_max ± its standard error says (`+0.5024 ± 0.0489`): chaotic or stable beyond two
/// standard errors, else marginal.
#[derive(Debug, PartialEq)]
enum Class {
    Chaotic,
    Stable,
    Marginal,
}

fn class(cell: &str) -> Class {
    let mut it = cell.split('±').map(|x| x.trim().parse::<f64>().unwrap());
    let (l, se) = (it.next().unwrap(), it.next().unwrap());
    match l {
        _ if l - 2.0 * se > 0.0 => Class::Chaotic,
        _ if l + 2.0 * se < 0.0 => Class::Stable,
        _ => Class::Marginal,
    }
}

/// Every variant in the book's order, with what its λ_max says and on which side of the joint
/// limits it ended. The printed numbers are the book's to the digit on this machine; a chaotic
/// run is not the same to the digit on another CPU's libm, so a row that differs only in its
/// digits is named, not failed. A variant whose edit did nothing (the feedback or the damping
/// off) changes class and fails.
#[test]
fn the_study_table_is_what_run_sh_prints() {
    let Some(python) = python_dir() else { return };
    let printed = script("run.sh", &python, &[("TABLE_ONLY", "1")]);
    let rows = printed_rows(&printed, "| variant");
    let book = book_rows("| variant | residual before → final");
    assert_eq!(rows.len(), book.len(), "{printed}");
    let side = |margin: &str| margin.parse::<f64>().unwrap() > 0.0;
    for (fresh, book) in rows.iter().zip(&book) {
        // The book names a variant and says what it is: `both (centring α = 20 + …)`.
        let name = book[0].split_whitespace().next().unwrap();
        assert_eq!(fresh[0], name, "row order");
        let (f, b) = (class(&fresh[6]), class(&book[6]));
        match b {
            Class::Marginal => assert_ne!(f, Class::Chaotic, "variant {name}: {fresh:?}"),
            _ => assert_eq!(
                f, b,
                "variant {name}: {fresh:?} against the book's {book:?}"
            ),
        }
        assert_eq!(side(&fresh[4]), side(&book[4]), "variant {name}: {fresh:?}");
        if fresh[1..] != book[1..] {
            eprintln!("variant {name}: {fresh:?}, the book {book:?} (digits only)");
        }
    }
}

/// Each variant's count of starts within one of the book's (a start at the edge of a limit may
/// fall either way on another CPU's libm), and the book's exact row on this machine.
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
        let (f, b) = (number(&fresh[3]), number(&book[3]));
        assert!(
            (f - b).abs() <= 1.0,
            "{fresh:?} against the book's {book:?}"
        );
        if fresh[3..] != book[3..] {
            eprintln!("{fresh:?}, the book {book:?} (one start at a limit's edge)");
        }
    }
}

/// The preset's rows near the ready pose (`VARIANTS=new scripts/panda-study/basins.sh near`,
/// `chaosctl starts` underneath: no Python) against the book's table of the preset, each count
/// of periodic starts within one of the book's.
#[test]
fn the_presets_basin_rows_are_what_basins_sh_prints() {
    let printed = script_with("basins.sh", &["near", "100"], None, &[("VARIANTS", "new")]);
    let rows = printed_rows(&printed, "| α");
    let book: Vec<_> = book_rows("| starts | α | k_d | μ | `null_speed` (rad/s) | periodic")
        .into_iter()
        .filter(|r| r[0] == "near the pose")
        .collect();
    assert_eq!(rows.len(), book.len(), "{printed}");
    for (fresh, book) in rows.iter().zip(&book) {
        for k in 0..3 {
            assert_eq!(
                number(&fresh[k]),
                number(&book[k + 1]),
                "{fresh:?} {book:?}"
            );
        }
        let speed = |c: &str| if c == "—" { 0.0 } else { number(c) };
        assert_eq!(number(&fresh[4]), speed(&book[4]), "{fresh:?} {book:?}");
        let (f, b) = (number(&fresh[5]), number(&book[5]));
        assert!(
            (f - b).abs() <= 1.0,
            "{fresh:?} against the book's {book:?}"
        );
    }
}
