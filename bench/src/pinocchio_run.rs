//! pinocchio timed in the same run as chaosd's robot model (issue 45): a ratio between two
//! runs on this VM moves by ±30 % with the host, so `compute` runs pinocchio's C++ harness
//! (`scripts/pinocchio-timings/run.sh`) itself, on the same core, just before its own model
//! table, and reads what it wrote. The harness needs Python (a venv with the `pin` wheel, made
//! and filled by the script when absent) and a C++ compiler; without them, or when it fails,
//! the table says why, and chaosd's own rows are timed as ever. A file of timings from another
//! run can still be given (`--pinocchio FILE`); the table then names it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Where pinocchio's timings come from.
#[derive(Clone, Debug)]
pub enum Source {
    /// Time pinocchio now with the script, using (or making) this venv.
    Now { venv: PathBuf },
    /// Timings another run wrote.
    File(PathBuf),
    /// Not at all (`--no-pinocchio`).
    Off,
}

/// The venv the script makes by default.
pub const DEFAULT_VENV: &str = "/tmp/pinvenv";

/// What `compute` has of pinocchio: the timings file to read, or why there is none.
#[derive(Clone, Debug)]
pub struct Timings {
    pub path: Option<PathBuf>,
    /// Said in the table when there is no file: "not timed: …".
    pub why_not: String,
    /// Measured by this run (not read from another's file).
    pub this_run: bool,
}

/// The script, found from this crate's source (the bench runs from its checkout).
fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/pinocchio-timings/run.sh")
}

/// Whether `program` is on `PATH`.
fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(program).is_file()))
}

/// Obtains the timings from `source`; a run of the script writes into `out_dir` and is pinned to
/// `core`, as chaosd's rows are. Never fails: a missing tool or a failed run is a reason.
pub fn obtain(source: &Source, quick: bool, core: usize, out_dir: &Path) -> Timings {
    let none = |why: String| Timings {
        path: None,
        why_not: why,
        this_run: false,
    };
    let venv = match source {
        Source::Off => return none("not timed (--no-pinocchio)".into()),
        Source::File(p) => {
            return Timings {
                path: Some(p.clone()),
                why_not: format!("no timings at {}", p.display()),
                this_run: false,
            }
        }
        Source::Now { venv } => venv,
    };
    let script = script();
    if !script.is_file() {
        return none(format!("not timed: {} is not here", script.display()));
    }
    let has_python = venv.join("bin/python").is_file() || on_path("python3");
    let missing: Vec<&str> = [("python3", has_python), ("g++", on_path("g++"))]
        .iter()
        .filter(|(_, ok)| !ok)
        .map(|(n, _)| *n)
        .collect();
    if !missing.is_empty() {
        return none(format!(
            "not timed: no {} on this machine (scripts/pinocchio-timings/run.sh needs Python and a C++ compiler)",
            missing.join(" and ")
        ));
    }
    let out = out_dir.join("pinocchio-timings.json");
    eprintln!(
        "chaosd-bench: compute: timing pinocchio with {} (its first run makes {} and compiles \
         for 4-6 minutes)",
        script.display(),
        venv.display()
    );
    let run = Command::new("bash")
        .arg(&script)
        .arg(venv)
        .arg(&out)
        .env("CORE", core.to_string())
        .env("QUICK", if quick { "1" } else { "0" })
        .output();
    match run {
        Ok(o) if o.status.success() && out.is_file() => Timings {
            path: Some(out),
            why_not: String::new(),
            this_run: true,
        },
        Ok(o) => {
            let err = String::from_utf8_lossy(&o.stderr);
            let last = err
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("");
            none(format!(
                "not timed: scripts/pinocchio-timings/run.sh failed ({}: {})",
                o.status,
                last.trim()
            ))
        }
        Err(e) => none(format!("not timed: cannot run bash: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_is_read_as_given_and_off_says_so() {
        let dir = std::env::temp_dir();
        let t = obtain(&Source::File("x.json".into()), true, 0, &dir);
        assert_eq!((t.path, t.this_run), (Some(PathBuf::from("x.json")), false));
        let t = obtain(&Source::Off, true, 0, &dir);
        assert!(
            t.path.is_none() && t.why_not.contains("--no-pinocchio"),
            "{t:?}"
        );
        assert!(script().is_file(), "{}", script().display());
    }
}
