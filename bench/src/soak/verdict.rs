//! The soak's verdict: what was injected, detected and recovered, what the processes cost, and
//! whether any data or resource was lost.

use super::schedule::{FaultKind, Options};
use super::system::{Lifetime, Status};
use super::windows::Checked;
use crate::stats::fmt_ns;
use std::collections::BTreeMap;
use std::time::Duration;

/// One injected fault and what the system reported.
#[derive(Clone, Debug)]
pub struct Episode {
    pub kind: FaultKind,
    /// Seconds since the soak started.
    pub at_s: f64,
    /// From the injection to the first report of it.
    pub detected: Option<Duration>,
    /// Whether a missing detection fails the soak (false for a hog without SCHED_FIFO).
    pub detection_required: bool,
    /// From the end of the fault to the first report of RUN.
    pub recovered: Option<Duration>,
    pub notes: Vec<String>,
}

impl Episode {
    pub fn new(kind: FaultKind, at_s: f64) -> Self {
        Self {
            kind,
            at_s,
            detected: None,
            detection_required: true,
            recovered: None,
            notes: Vec::new(),
        }
    }

    pub fn note(&mut self, n: &str) {
        self.notes.push(n.to_string());
    }
}

/// RSS and fds over one role's lifetimes.
#[derive(Clone, Debug, Default)]
pub struct Lives {
    pub count: usize,
    pub first: Option<(u64, usize)>,
    pub last: Option<(u64, usize)>,
    /// Least-squares RSS slope of the longest lifetime (MB/h) and its span (s), after its
    /// first 2 s.
    pub growth: Option<(f64, f64)>,
    pub ends: BTreeMap<String, usize>,
}

impl Lives {
    pub fn of(lives: &[Lifetime]) -> Self {
        let mut l = Lives {
            count: lives.len(),
            ..Default::default()
        };
        l.first = lives
            .iter()
            .find_map(|x| x.samples.get(1).or(x.samples.first()))
            .map(|s| (s.rss_kb, s.fds));
        l.last = lives
            .iter()
            .rev()
            .find_map(|x| x.samples.last())
            .map(|s| (s.rss_kb, s.fds));
        for x in lives {
            *l.ends
                .entry(x.end.clone().unwrap_or_else(|| "running".into()))
                .or_default() += 1;
        }
        let longest = lives.iter().max_by_key(|x| x.samples.len());
        if let Some(x) = longest {
            let t0 = x.samples.first().map(|s| s.at);
            let pts: Vec<(f64, f64)> = x
                .samples
                .iter()
                .map(|s| {
                    let t = t0.map_or(0.0, |t0| (s.at - t0).as_secs_f64());
                    (t, s.rss_kb as f64 / 1024.0)
                })
                .filter(|(t, _)| *t >= 2.0)
                .collect();
            if pts.len() >= 3 {
                let n = pts.len() as f64;
                let (mx, my) = (
                    pts.iter().map(|p| p.0).sum::<f64>() / n,
                    pts.iter().map(|p| p.1).sum::<f64>() / n,
                );
                let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
                let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
                if sxx > 0.0 {
                    let span = pts.last().map_or(0.0, |p| p.0) - pts[0].0;
                    l.growth = Some((sxy / sxx * 3600.0, span));
                }
            }
        }
        l
    }
}

#[derive(Debug, Default)]
pub struct Verdict {
    pub seed: u64,
    pub namespace: String,
    pub planned_seconds: f64,
    pub seconds: f64,
    pub episodes: Vec<Episode>,
    pub windows: Vec<Checked>,
    pub windows_cut: u32,
    pub windows_unchecked: u32,
    /// Last status per daemon pid.
    pub last_status: BTreeMap<u64, Status>,
    pub clean_stops: u32,
    /// (ticks, records that reached the reporter) of the final daemon lifetime.
    pub final_ticks: Option<(u64, u64)>,
    pub lives: (Lives, Lives),
    pub leftovers: Vec<String>,
    /// (services, nodes) tracked for the leftover check.
    pub tracked: (usize, usize),
    pub failures: Vec<String>,
}

fn ms(d: Option<Duration>) -> String {
    d.map_or_else(|| "-".into(), |d| fmt_ns(d.as_nanos() as f64))
}

fn mb(kb: u64) -> String {
    format!("{:.1} MB", kb as f64 / 1024.0)
}

impl Verdict {
    pub fn new(opts: &Options, ns: &str) -> Self {
        Self {
            seed: opts.seed,
            namespace: ns.to_string(),
            planned_seconds: opts.seconds,
            ..Default::default()
        }
    }

    pub fn fail(&mut self, why: String) {
        self.failures.push(why);
    }

    pub fn note_status(&mut self, s: &Status) {
        self.last_status.insert(s.pid, s.clone());
    }

    /// Every reason the soak fails, the recorded ones and those read off the tables.
    pub fn all_failures(&self) -> Vec<String> {
        let mut f = self.failures.clone();
        for e in &self.episodes {
            if e.detection_required && e.detected.is_none() {
                f.push(format!(
                    "{} at {:.1} s was not detected",
                    e.kind.label(),
                    e.at_s
                ));
            }
            if e.recovered.is_none() {
                f.push(format!(
                    "{} at {:.1} s did not recover",
                    e.kind.label(),
                    e.at_s
                ));
            }
        }
        let drops: u64 = self.last_status.values().map(|s| s.telemetry_dropped).sum();
        if drops > 0 {
            f.push(format!("{drops} telemetry records dropped"));
        }
        if self.windows.is_empty() {
            f.push("no recording window was checked".into());
        }
        for l in &self.leftovers {
            f.push(format!("left behind: {l}"));
        }
        f
    }

    pub fn passed(&self) -> bool {
        self.all_failures().is_empty()
    }

    pub fn render(&self, command: &str) -> String {
        let mut t = String::new();
        let date = crate::report::now_utc();
        t.push_str(&format!(
            "## Soak\n\n`{command}`: {date}, seed {}, {:.0} s planned, {:.1} s run, namespace `{}`.\n\n",
            self.seed, self.planned_seconds, self.seconds, self.namespace
        ));
        t.push_str("| fault | injected | detected | recovered | worst detection | worst recovery | notes |\n|---|---|---|---|---|---|---|\n");
        for k in FaultKind::ALL {
            let es: Vec<&Episode> = self.episodes.iter().filter(|e| e.kind == k).collect();
            if es.is_empty() {
                t.push_str(&format!("| {} | 0 | - | - | - | - | |\n", k.label()));
                continue;
            }
            let det = es.iter().filter(|e| e.detected.is_some()).count();
            let req = es.iter().filter(|e| e.detection_required).count();
            let rec = es.iter().filter(|e| e.recovered.is_some()).count();
            let wd = es.iter().filter_map(|e| e.detected).max();
            let wr = es.iter().filter_map(|e| e.recovered).max();
            let mut notes: Vec<String> = es.iter().flat_map(|e| e.notes.clone()).collect();
            notes.sort();
            notes.dedup();
            if notes.len() > 3 {
                let n = notes.len();
                notes.truncate(2);
                notes.push(format!("… ({n} notes)"));
            }
            let det = if req < es.len() {
                format!("{det} ({req} required)")
            } else {
                det.to_string()
            };
            t.push_str(&format!(
                "| {} | {} | {det} | {rec} | {} | {} | {} |\n",
                k.label(),
                es.len(),
                ms(wd),
                ms(wr),
                notes.join("; ")
            ));
        }
        t.push_str("\n| process | lifetimes | RSS start | RSS end | RSS growth (longest lifetime) | fds start | fds end |\n|---|---|---|---|---|---|---|\n");
        for (name, l) in [("chaosd", &self.lives.0), ("chaosd-plant", &self.lives.1)] {
            let growth = l.growth.map_or_else(
                || "-".into(),
                |(g, span)| format!("{g:+.2} MB/h over {span:.0} s"),
            );
            t.push_str(&format!(
                "| {name} | {} | {} | {} | {growth} | {} | {} |\n",
                l.count,
                l.first.map_or("-".into(), |x| mb(x.0)),
                l.last.map_or("-".into(), |x| mb(x.0)),
                l.first.map_or("-".into(), |x| x.1.to_string()),
                l.last.map_or("-".into(), |x| x.1.to_string()),
            ));
        }
        let rows: u64 = self.windows.iter().map(|w| w.rows_file).sum();
        let acc: u64 = self.windows.iter().map(|w| w.accepted).sum();
        let ticks: u64 = self.windows.iter().map(|w| w.ticks).sum();
        let lost = self.windows.iter().filter(|w| w.lost()).count();
        let drops: u64 = self.last_status.values().map(|s| s.telemetry_dropped).sum();
        let all_ticks: u64 = self.last_status.values().map(|s| s.ticks).sum();
        let overruns: u64 = self.last_status.values().map(|s| s.overruns).sum();
        t.push_str(&format!(
            "\n| data | value |\n|---|---|\n\
             | recording windows checked (lost) | {} ({lost}); {} cut by kill -9, {} unchecked |\n\
             | rows written / states accepted / ticks, in checked windows | {rows} / {acc} / {ticks} |\n\
             | telemetry records dropped (all daemon lifetimes) | {drops} |\n\
             | final daemon: records at the reporter / ticks | {} |\n\
             | clean stops with their summaries | {} |\n\
             | overruns / ticks (all daemon lifetimes) | {overruns} / {all_ticks} |\n\
             | leftovers (processes, services, nodes, files) after the end | {} (checked {} services, {} nodes) |\n",
            self.windows.len(),
            self.windows_cut,
            self.windows_unchecked,
            self.final_ticks
                .map_or("-".into(), |(t, r)| format!("{r} / {t}")),
            self.clean_stops,
            self.leftovers.len(),
            self.tracked.0,
            self.tracked.1,
        ));
        let f = self.all_failures();
        if f.is_empty() {
            t.push_str("\n**Verdict: PASS**\n");
        } else {
            t.push_str(&format!("\n**Verdict: FAIL**\n\n- {}\n", f.join("\n- ")));
        }
        t
    }
}
