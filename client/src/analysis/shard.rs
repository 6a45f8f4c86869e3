//! Sharded scans: `--shard i/n` runs one slice of a scan's grid on one machine, and
//! `chaosctl merge` puts the slices back together into exactly the unsharded result.
//!
//! **Assignment.** A scan (`sweep`, `basins`, `obstacles`) lists its grid points in one fixed
//! order, the order of the rows of its CSV. Point k (counting from 0) belongs to shard k mod n,
//! and shards are numbered 0 … n−1, like `SLURM_ARRAY_TASK_ID` with `--array=0-(n-1)` and a
//! Kubernetes Indexed Job's `JOB_COMPLETION_INDEX`. Every shard gets every n-th point, so cheap
//! and expensive corners of the grid spread over all shards.
//!
//! **The shard file** (`PREFIX.shard-I-of-N.json`) is self-describing: the command and its full
//! argument list (the grid spec), a fingerprint of every point's configuration, the number of
//! points, which shard it is, and each of its points' raw results. `merge` parses the recorded
//! arguments again, rebuilds the grid, refuses files whose fingerprint, command or shard count
//! differ, refuses a point given twice, names every missing point, and then runs the same
//! finishing code as the unsharded scan (CSV, plot, table). Floats are carried exactly
//! (`serde_json` with `float_roundtrip`); a result that JSON cannot carry exactly (a NaN or an
//! infinity) is refused when the shard is written, not discovered at merge time.

use super::parallel::run_all;
use anyhow::{anyhow, bail, Context, Result};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use std::fmt::Debug;
use std::path::{Path, PathBuf};

/// The shard file's format tag; a merge refuses any other.
pub const FORMAT: &str = "chaosctl-shard/1";

/// Shard counts above this are refused (a typo rather than a cluster).
pub const MAX_SHARDS: usize = 1_000_000;

/// `--shard i/n`: this process runs the points k with k mod n = i.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// Parses `I/N` with 0 ≤ I < N.
pub fn parse_shard(s: &str) -> Result<Shard, String> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| format!("{s:?}: expected I/N, e.g. 0/4 (shards are numbered 0 to N-1)"))?;
    let count: usize = n
        .trim()
        .parse()
        .ok()
        .filter(|n| (1..=MAX_SHARDS).contains(n))
        .ok_or_else(|| format!("{s:?}: N must be a whole number from 1 to {MAX_SHARDS}"))?;
    let index: usize = i
        .trim()
        .parse()
        .ok()
        .filter(|i| *i < count)
        .ok_or_else(|| {
            format!(
                "{s:?}: I must be a whole number from 0 to {} (shards are numbered from 0)",
                count - 1
            )
        })?;
    Ok(Shard { index, count })
}

impl Shard {
    /// The grid points of this shard, in grid order.
    pub fn points(&self, total: usize) -> Vec<usize> {
        (self.index..total).step_by(self.count).collect()
    }

    /// `PREFIX.shard-I-of-N.json`.
    pub fn file(&self, prefix: &Path) -> PathBuf {
        crate::plot::with_ext(
            prefix,
            &format!("shard-{}-of-{}.json", self.index, self.count),
        )
    }
}

/// A scan's grid as a merge checks it: its command, a fingerprint of every point, and a label per
/// point for naming missing ones.
pub struct Grid {
    pub command: &'static str,
    pub fingerprint: String,
    pub labels: Vec<String>,
}

impl Grid {
    /// `parts` describe the whole grid (each point's configuration and the run settings) as text;
    /// the fingerprint is FNV-1a 64 over them, stable across builds and machines.
    pub fn new(
        command: &'static str,
        parts: impl IntoIterator<Item = String>,
        labels: Vec<String>,
    ) -> Self {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for p in parts {
            for b in p.bytes().chain([0u8]) {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
        Self {
            command,
            fingerprint: format!("{h:016x}-{}", labels.len()),
            labels,
        }
    }

    pub fn len(&self) -> usize {
        self.labels.len()
    }
}

#[derive(Serialize, Deserialize)]
struct Point<R> {
    point: usize,
    result: R,
}

#[derive(Serialize, Deserialize)]
struct File<R> {
    format: String,
    command: String,
    /// chaosctl's arguments, from the subcommand on (the grid spec; `merge` parses them again).
    args: Vec<String>,
    grid: String,
    points: usize,
    shard: usize,
    shards: usize,
    results: Vec<Point<R>>,
}

/// Runs this shard's points (`f` on each, on `jobs` threads) and writes the shard file.
pub fn run_shard<T: Sync, R: Send + Serialize + DeserializeOwned + Debug>(
    grid: &Grid,
    shard: Shard,
    items: &[T],
    prefix: &Path,
    jobs: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Result<PathBuf> {
    assert_eq!(grid.len(), items.len(), "one label per grid point");
    let mine = shard.points(items.len());
    let results = run_all(&mine, jobs, grid.command, |&k| f(&items[k]))?;
    let results: Vec<Point<R>> = mine
        .iter()
        .zip(results)
        .map(|(&point, result)| Point { point, result })
        .collect();
    for p in &results {
        exact(&p.result)
            .with_context(|| format!("point {} ({})", p.point, grid.labels[p.point]))?;
    }
    let file = File {
        format: FORMAT.into(),
        command: grid.command.into(),
        // Lossy for a non-UTF-8 argument: merge then finds another grid and says so.
        args: std::env::args_os()
            .skip(1)
            .map(|a| a.to_string_lossy().into_owned())
            .collect(),
        grid: grid.fingerprint.clone(),
        points: items.len(),
        shard: shard.index,
        shards: shard.count,
        results,
    };
    let path = shard.file(prefix);
    let text = serde_json::to_string(&file)?;
    std::fs::write(&path, text + "\n")
        .with_context(|| format!("cannot write {}", path.display()))?;
    println!(
        "{}: shard {}/{}: {} of {} points",
        grid.command,
        shard.index,
        shard.count,
        mine.len(),
        items.len()
    );
    super::print_written(std::slice::from_ref(&path));
    Ok(path)
}

/// A scan's points (`what` names it on the progress bar), run whole (`Some`, every result in
/// grid order) or as shard `shard` (`None`: this shard's file is written and the scan's own
/// finishing waits for `chaosctl merge`). The grid is built only for a shard, where it names
/// the file's points.
pub fn run_or_shard<T: Sync, R: Send + Serialize + DeserializeOwned + Debug>(
    what: &str,
    shard: Option<Shard>,
    grid: impl FnOnce() -> Grid,
    items: &[T],
    prefix: &Path,
    jobs: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Result<Option<Vec<R>>> {
    match shard {
        Some(s) => {
            run_shard(&grid(), s, items, prefix, jobs, f)?;
            Ok(None)
        }
        None => run_all(items, jobs, what, f).map(Some),
    }
}

/// Refuses a result that does not come back from JSON as it went in (a NaN or an infinity
/// becomes `null`). Debug prints every float in its shortest exact form, so equal Debug text
/// means equal values.
fn exact<R: Serialize + DeserializeOwned + Debug>(r: &R) -> Result<()> {
    let back: R = serde_json::from_str(&serde_json::to_string(r)?)?;
    if format!("{r:?}") != format!("{back:?}") {
        bail!(
            "its result holds a number a shard file cannot carry exactly (NaN or infinite): run \
             this grid unsharded"
        );
    }
    Ok(())
}

/// A shard file as read by `merge`, its results not yet decoded.
pub struct Loaded {
    pub path: PathBuf,
    pub command: String,
    pub args: Vec<String>,
    grid: String,
    points: usize,
    shard: usize,
    shards: usize,
    results: Vec<Point<serde_json::Value>>,
}

/// Reads the shard files and checks that they belong together (same format, command, arguments,
/// grid and shard count; no shard twice). Returns them sorted by shard.
pub fn load(paths: &[PathBuf]) -> Result<Vec<Loaded>> {
    if paths.is_empty() {
        bail!("give the shard files to merge");
    }
    let mut files = Vec::with_capacity(paths.len());
    for path in paths {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        let f: File<serde_json::Value> = serde_json::from_str(&text).map_err(|e| {
            anyhow!(
                "{}: not a chaosctl shard file ({e}); shard files are written by sweep, basins, \
                 obstacles or starts with --shard I/N",
                path.display()
            )
        })?;
        if f.format != FORMAT {
            bail!(
                "{}: format {:?}, but this chaosctl reads {FORMAT:?}",
                path.display(),
                f.format
            );
        }
        if f.shards == 0 || f.shard >= f.shards {
            bail!(
                "{}: shard {}/{} is not a valid shard",
                path.display(),
                f.shard,
                f.shards
            );
        }
        files.push(Loaded {
            path: path.clone(),
            command: f.command,
            args: f.args,
            grid: f.grid,
            points: f.points,
            shard: f.shard,
            shards: f.shards,
            results: f.results,
        });
    }
    let first = &files[0];
    for f in &files[1..] {
        let differs = |what: &str, a: &dyn Debug, b: &dyn Debug| {
            anyhow!(
                "{} and {} are shards of different scans: {what} {a:?} vs {b:?}",
                first.path.display(),
                f.path.display()
            )
        };
        if f.command != first.command {
            return Err(differs("command", &first.command, &f.command));
        }
        if f.grid != first.grid || f.points != first.points {
            return Err(differs("grid", &first.grid, &f.grid));
        }
        if f.shards != first.shards {
            return Err(differs("shard count", &first.shards, &f.shards));
        }
    }
    files.sort_by_key(|f| f.shard);
    for w in files.windows(2) {
        if w[0].shard == w[1].shard {
            bail!(
                "shard {}/{} given twice: {} and {}",
                w[0].shard,
                w[0].shards,
                w[0].path.display(),
                w[1].path.display()
            );
        }
    }
    Ok(files)
}

/// The results of every grid point, in grid order, from shard files that `load` accepted.
/// Refuses files computed for another grid, points outside their shard or given twice, and names
/// every missing point.
pub fn collect<R: DeserializeOwned>(grid: &Grid, files: Vec<Loaded>) -> Result<Vec<R>> {
    let total = grid.len();
    let mut out: Vec<Option<R>> = (0..total).map(|_| None).collect();
    let shards = files.first().map_or(1, |f| f.shards);
    let mut present = vec![false; shards];
    for f in files {
        if f.command != grid.command {
            bail!(
                "{}: a {} shard, merged as {}",
                f.path.display(),
                f.command,
                grid.command
            );
        }
        if f.grid != grid.fingerprint {
            bail!(
                "{}: computed for another grid than its recorded arguments give now \
                 ({} points then, {total} now; fingerprint {} then, {} now): did a config file \
                 change, or is merge running in another directory than the shards?",
                f.path.display(),
                f.points,
                f.grid,
                grid.fingerprint
            );
        }
        present[f.shard] = true;
        for p in f.results {
            if p.point >= total || p.point % f.shards != f.shard {
                bail!(
                    "{}: point {} does not belong to shard {}/{} of a {total}-point grid",
                    f.path.display(),
                    p.point,
                    f.shard,
                    f.shards
                );
            }
            if out[p.point].is_some() {
                bail!(
                    "{}: point {} ({}) given twice",
                    f.path.display(),
                    p.point,
                    grid.labels[p.point]
                );
            }
            let r = serde_json::from_value(p.result).with_context(|| {
                format!("{}: point {}: malformed result", f.path.display(), p.point)
            })?;
            out[p.point] = Some(r);
        }
    }
    let missing: Vec<usize> = (0..total).filter(|&k| out[k].is_none()).collect();
    if !missing.is_empty() {
        let absent: Vec<String> = (0..shards)
            .filter(|&s| !present[s])
            .map(|s| format!("{s}/{shards}"))
            .collect();
        let named: Vec<String> = missing
            .iter()
            .take(20)
            .map(|&k| format!("point {k} ({})", grid.labels[k]))
            .collect();
        bail!(
            "incomplete: {} of {total} points missing{}: {}{}",
            missing.len(),
            if absent.is_empty() {
                String::new()
            } else {
                format!(" (no file for shard {})", absent.join(", "))
            },
            named.join(", "),
            if missing.len() > named.len() {
                format!(", and {} more", missing.len() - named.len())
            } else {
                String::new()
            }
        );
    }
    Ok(out.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_specs_parse_and_reject() {
        assert_eq!(parse_shard("0/4"), Ok(Shard { index: 0, count: 4 }));
        assert_eq!(parse_shard("3/4"), Ok(Shard { index: 3, count: 4 }));
        for bad in ["4/4", "1/0", "-1/4", "1", "a/b", "1/4/2", "", "/4"] {
            assert!(parse_shard(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn every_point_in_exactly_one_shard() {
        for n in [1, 2, 3, 7] {
            let mut seen = [0; 20];
            for i in 0..n {
                for k in (Shard { index: i, count: n }).points(20) {
                    assert_eq!(k % n, i);
                    seen[k] += 1;
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "n = {n}");
        }
    }

    #[test]
    fn fingerprint_depends_on_every_part() {
        let g = |p: &[&str]| Grid::new("x", p.iter().map(|s| s.to_string()), vec![]).fingerprint;
        assert_eq!(g(&["a", "b"]), g(&["a", "b"]));
        assert_ne!(g(&["a", "b"]), g(&["a", "c"]));
        assert_ne!(g(&["ab"]), g(&["a", "b"]));
    }

    #[test]
    fn non_finite_results_are_refused() {
        assert!(exact(&Some(1.0f64 / 3.0)).is_ok());
        assert!(exact(&Some(f64::NAN)).is_err());
        assert!(exact(&(f64::INFINITY, 1.0)).is_err());
    }
}
