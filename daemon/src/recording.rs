//! Recordings (`chaosctl record start|stop`): the states the law used and the commands it sent,
//! written by the reporter thread, never by the loop. MCAP by default
//! ([`crate::mcap_recording`]); a name ending in `.csv` gets one CSV row per answered state
//! ([`CsvRecording`], the same columns `chaosctl export --csv` writes from an MCAP file).
//!
//! A recording stays in the output directory ([`crate::requests::recording_path`] refuses
//! absolute paths, `..` and symbolic links) and is owner-only ([`rt::files`]). Every recording
//! file is opened in one place, [`crate::recording_files::open`].

use crate::recording_files::resolve;
use crate::telemetry::TickRecord;
use protocol::StateSample;
use std::io::Write;
use std::path::{Path, PathBuf};

/// An open recording of either format.
pub enum Recording {
    Csv(CsvRecording),
    Mcap(Box<crate::mcap_recording::McapRecording>),
}

impl Recording {
    /// Starts a recording named `name` (empty: `recording-<unix seconds>.mcap`): CSV when the
    /// name ends in `.csv`, else MCAP.
    pub fn start(
        out_dir: &Path,
        name: &str,
        system: &control::System,
        rate_hz: f64,
        limit: crate::rotate::Limit,
    ) -> Result<Self, String> {
        if name.trim().ends_with(".csv") {
            return CsvRecording::start(out_dir, name, system.n(), limit).map(Recording::Csv);
        }
        crate::mcap_recording::McapRecording::start(out_dir, name, system, rate_hz, limit)
            .map(|r| Recording::Mcap(Box::new(r)))
    }

    pub fn path(&self) -> &Path {
        match self {
            Recording::Csv(r) => &r.path,
            Recording::Mcap(r) => &r.path,
        }
    }

    /// Rows (answered states) written so far.
    pub fn rows(&self) -> u64 {
        match self {
            Recording::Csv(r) => r.rows,
            Recording::Mcap(r) => r.rows(),
        }
    }

    /// One tick whose law ran on `st`.
    pub fn tick(
        &mut self,
        r: &TickRecord,
        st: &StateSample,
        ctx: crate::view::TickContext,
    ) -> Result<(), String> {
        match self {
            Recording::Csv(rec) => rec.write_row(r, st, ctx.chaos).map_err(|e| e.to_string()),
            Recording::Mcap(rec) => rec.tick(r, st, ctx),
        }
    }

    /// An operator's change (MCAP only: a CSV has no place for it): an event in `text`, and
    /// the new configuration's scene when it changed.
    pub fn note(&mut self, text: &str, system: Option<&control::System>) -> Result<(), String> {
        match self {
            Recording::Csv(_) => Ok(()),
            Recording::Mcap(r) => r.note(text, system),
        }
    }

    /// Closes the file; the JSON answer to `record stop`.
    pub fn finish(self) -> Result<String, String> {
        match self {
            Recording::Csv(r) => r.finish(),
            Recording::Mcap(r) => r.finish(),
        }
    }
}

/// The CSV columns of an `n`-joint arm (no line end).
pub fn csv_header(n: usize) -> String {
    let mut h = String::from("t,state_seq,state_stamp_ns,phi");
    for p in ["q", "qd"] {
        for i in 1..=n {
            h.push_str(&format!(",{p}{i}"));
        }
    }
    h.push_str(",command_seq,mode");
    for i in 1..=n {
        h.push_str(&format!(",qdd{i}"));
    }
    h + ",tracking_error,period_residual,null_residual,mu,chaos"
}

/// An open CSV recording.
pub struct CsvRecording {
    pub path: PathBuf,
    file: crate::rotate::RotatingWriter,
    pub rows: u64,
    n: usize,
}

impl CsvRecording {
    /// Starts a CSV recording for an `n`-joint arm named `name` inside `out_dir`, rotating at
    /// `limit` (`[daemon] record_max_bytes`, keeping `record_keep` old files; see `rotate`).
    pub fn start(
        out_dir: &Path,
        name: &str,
        n: usize,
        limit: crate::rotate::Limit,
    ) -> Result<Self, String> {
        let path = resolve(out_dir, name, "csv")?;
        let h = csv_header(n) + "\n";
        let file = crate::rotate::RotatingWriter::create(&path, h.as_bytes(), limit)
            .map_err(|e| format!("cannot create {}: {e}", path.display()))?;
        Ok(Self {
            path,
            file,
            rows: 0,
            n,
        })
    }

    /// Writes one row: the state the law used and the command that answered it.
    /// `chaos` is the monitor's verdict at this row.
    pub fn write_row(
        &mut self,
        r: &TickRecord,
        s: &StateSample,
        chaos: control::monitor::Verdict,
    ) -> std::io::Result<()> {
        let n = self.n;
        let f = &mut self.file;
        write!(f, "{:.6},{},{},{:.12e}", r.t, s.seq, s.stamp_ns, s.phi)?;
        for v in s.q[..n].iter().chain(&s.qd[..n]) {
            write!(f, ",{v:.12e}")?;
        }
        match &r.command {
            Some(c) => {
                write!(f, ",{},{}", c.seq, c.mode)?;
                for v in &c.qdd[..n] {
                    write!(f, ",{v:.12e}")?;
                }
            }
            None => {
                write!(f, ",,")?;
                for _ in 0..n {
                    write!(f, ",")?;
                }
            }
        }
        writeln!(
            f,
            ",{:.9e},{:.9e},{:.9e},{:.9e},{}",
            r.tracking_error,
            r.period_residual,
            r.null_residual,
            r.mu,
            chaos.name()
        )?;
        self.rows += 1;
        Ok(())
    }

    /// Flushes the file; the JSON answer to `record stop`.
    pub fn finish(mut self) -> Result<String, String> {
        self.file
            .flush()
            .map(|_| {
                serde_json::json!({
                    "path": self.path,
                    "format": "csv",
                    "rows": self.rows,
                    "rotations": self.file.rotations(),
                    "last_file": self.file.current_path(),
                })
                .to_string()
            })
            .map_err(|e| format!("cannot finish {}: {e}", self.path.display()))
    }
}
