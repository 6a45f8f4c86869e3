//! Recording windows: the exact "rows vs ticks" check.
//!
//! The daemon writes one recording row for every tick on which the law ran, and the law runs
//! exactly on the ticks that accept a fresh state (`fresh_states`), unless the daemon is in
//! FAULT. The loop counts `fresh_states` itself, in every record it hands the reporter, even for
//! records the reporter never gets (a full queue drops the record, not the count). So over a
//! window that opens and closes at known ticks,
//!
//! ```text
//! rows written == fresh_states(close) − fresh_states(open)
//! ```
//!
//! holds exactly when no row was lost, whatever the cause (a dropped record, a write error, a
//! torn file). A boundary is made exact by sending `status`, `record start` (or `stop`) and
//! `status` together: the reporter handles every queued request between two batches of
//! records, so if both statuses report the same tick count, no record was handled between
//! them, and the boundary lies at that tick. If they differ (the requests straddled a batch),
//! a start is undone and tried again, and a stop leaves its window unchecked (counted as such).

use super::system::{Control, Status};
use anyhow::{anyhow, bail, Result};
use iceoryx2::prelude::ipc;
use protocol::Op;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// An open recording window.
#[derive(Clone, Debug)]
pub struct Open {
    pub name: String,
    pub at: Status,
}

/// A closed, checked window.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Checked {
    pub rows_file: u64,
    pub rows_daemon: u64,
    pub accepted: u64,
    pub ticks: u64,
}

impl Checked {
    pub fn lost(&self) -> bool {
        self.rows_file != self.accepted || self.rows_daemon != self.accepted
    }
}

/// Counts the data rows of a recording (lines after the header) and checks the last one is
/// complete.
pub fn count_rows(path: &Path) -> Result<u64> {
    let text = std::fs::read(path).map_err(|e| anyhow!("cannot read {}: {e}", path.display()))?;
    if !text.is_empty() && text.last() != Some(&b'\n') {
        bail!("{} ends in a torn row", path.display());
    }
    let lines = text.iter().filter(|&&b| b == b'\n').count() as u64;
    Ok(lines.saturating_sub(1))
}

fn rows_of(body: &str) -> Option<u64> {
    serde_json::from_str::<serde_json::Value>(body).ok()?["rows"].as_u64()
}

/// What one attempt at a window boundary gave.
pub enum Boundary {
    /// Done at `at`; for a stop, the rows the daemon says it wrote.
    Done { at: Status, rows: Option<u64> },
    /// The two statuses straddled a batch of records: the boundary is not exact.
    Straddled,
    /// The daemon did not answer everything.
    NoAnswer,
}

/// Starts (`Op::RecordStart`, with the file name) or stops (`Op::RecordStop`) a recording
/// between two statuses, all sent together (see the module docs).
pub fn boundary(
    ctl: &mut Control,
    node: &iceoryx2::node::Node<ipc::Service>,
    op: Op,
    args: &str,
) -> Result<Boundary> {
    let reqs = [(Op::Status, ""), (op, args), (Op::Status, "")];
    let answers = ctl.batch(node, &reqs, Duration::from_secs(3));
    let [Some(a), Some(r), Some(b)] = <[Option<_>; 3]>::try_from(answers).expect("three answers")
    else {
        return Ok(Boundary::NoAnswer);
    };
    let a = Status::parse(&a.map_err(|e| anyhow!("status refused: {e}"))?)?;
    let b = Status::parse(&b.map_err(|e| anyhow!("status refused: {e}"))?)?;
    let rows = match (op, r) {
        (Op::RecordStop, Ok(body)) => {
            Some(rows_of(&body).ok_or_else(|| anyhow!("record stop said {body}"))?)
        }
        (_, Ok(_)) => None,
        (_, Err(why)) => bail!("{op:?} refused: {why}"),
    };
    if a.ticks != b.ticks || a.pid != b.pid {
        return Ok(Boundary::Straddled);
    }
    Ok(Boundary::Done { at: a, rows })
}

/// Checks a closed window against the daemon's own counts.
pub fn check(dir: &Path, open: &Open, close: &Status, rows_daemon: u64) -> Result<Checked> {
    if close.faults != open.at.faults || close.mode == "Fault" {
        bail!("the daemon went into FAULT during window {}", open.name);
    }
    let path: PathBuf = dir.join(&open.name);
    Ok(Checked {
        rows_file: count_rows(&path)?,
        rows_daemon,
        accepted: close.fresh - open.at.fresh,
        ticks: close.ticks - open.at.ticks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_counted_and_a_torn_row_is_refused() {
        let d = std::env::temp_dir().join(format!("soak-rows-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let p = d.join("r.csv");
        std::fs::write(&p, "t,a\n1,2\n3,4\n").unwrap();
        assert_eq!(count_rows(&p).unwrap(), 2);
        std::fs::write(&p, "t,a\n").unwrap();
        assert_eq!(count_rows(&p).unwrap(), 0);
        std::fs::write(&p, "t,a\n1,2\n3,").unwrap();
        assert!(count_rows(&p).is_err());
        let c = Checked {
            rows_file: 5,
            rows_daemon: 5,
            accepted: 6,
            ticks: 7,
        };
        assert!(c.lost());
        assert!(!Checked { accepted: 5, ..c }.lost());
        std::fs::remove_dir_all(&d).ok();
    }
}
