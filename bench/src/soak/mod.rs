//! `chaosd-bench soak`: the real daemon and plant for N seconds under injected faults, judged by
//! what the system itself reports.
//!
//! The soak starts `chaosd` and `chaosd-plant` in a namespace and output directory of their own,
//! then injects, at times drawn from the seed ([`schedule`]), one fault at a time:
//!
//! | fault | injected as | detected when the system reports | recovered when |
//! |---|---|---|---|
//! | kill -9 plant | SIGKILL, restart after a pause | daemon: HOLD entered (`holds_entered` up) | daemon: `plant_restarts` up, RUN |
//! | kill -9 daemon | SIGKILL, restart after a pause | plant: `COMMAND_TIMEOUT` in its states | the new daemon answers, RUN |
//! | SIGSTOP plant | SIGSTOP, SIGCONT after a pause | daemon: HOLD entered | RUN |
//! | SIGSTOP daemon | SIGSTOP, SIGCONT after a pause | daemon: `overruns` up | RUN |
//! | CPU hog | a thread busy on the loop's core, SCHED_FIFO one above the loop | daemon: `overruns` up, or plant: `COMMAND_TIMEOUT` | RUN |
//! | rogue publisher | the plant stopped cleanly; garbage states (wrong size, NaN, stamped 5 s ahead, an old sequence number) on the state service | daemon: `rejected_invalid`, `rejected_future` and `rejected_out_of_order` each up, and no state accepted | plant restarted, RUN |
//! | request burst | 50-300 status/get/set requests, six in flight | every request answered | every accepted `set` applied (`params_applied`, `mu`), RUN |
//!
//! "RUN" always means: the daemon answers `status` with mode Run, its `fresh_states` count moves
//! between two answers, and the plant's newest state carries neither `COMMAND_TIMEOUT` nor
//! `BRAKING`. Recovery time runs from the end of the fault (the restart, the SIGCONT, the hog's
//! or the rogue's end, the burst's last answer) to the first answer that shows RUN. The rogue
//! also checks that a second state publisher is refused while the plant runs (iceoryx2's
//! `max_publishers = 1`). A hog that cannot get SCHED_FIFO (no privilege) runs at the normal
//! priority; it may then do no harm, so its detection is reported but not required.
//!
//! **Data lost** means any of:
//! * a recording window whose rows differ from the states the loop accepted over it (see
//!   [`windows`]: exact, per window, from the loop's own `fresh_states` count); windows open
//!   when the daemon is SIGKILLed are cut (a killed process loses its buffered rows by
//!   definition) and counted apart, never as checked;
//! * `telemetry_dropped` > 0 in any daemon lifetime (its last answered status);
//! * at the final clean stop: a missing `daemon-summary.json` or `plant-summary.json`, or a
//!   daemon summary whose latency histogram holds fewer records than the loop's ticks (a record
//!   that never reached the reporter);
//! * a missing `plant-summary.json` after any clean plant stop (the rogue episodes stop it with
//!   SIGTERM).
//!
//! The soak fails (exit 1) if data was lost, a fault was not detected (where detection is
//! required) or not recovered within [`RECOVERY_LIMIT`], a garbage state was accepted, a
//! process died by itself, a clean stop was not clean, or anything is left after the end:
//! a process with the soak's config, an iceoryx2 service of its namespace, a node of one of its
//! processes, or a file of either ([`leftovers`]). RSS and open fds of both processes are
//! sampled every second (all samples in `resources.csv`); RSS growth is reported (the longest
//! lifetime, least squares), not judged: a run with kills has lifetimes too short for a per-hour
//! rate to mean much.
//!
//! Every process the soak starts is owned by a [`crate::child::Child`] guard (SIGKILL on drop,
//! `PR_SET_PDEATHSIG`), a stopped process is continued on every path, and the hog is a thread
//! of this process, so nothing outlives the soak.

pub mod leftovers;
pub mod schedule;
pub mod system;
pub mod verdict;
pub mod windows;

use crate::book::names;
use anyhow::{anyhow, bail, Context, Result};
use iceoryx2::prelude::ipc;
use protocol::{flags, Op, ServiceNames, StateSample};
use schedule::{Fault, FaultKind, Options, Rng};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use system::{Control, Role, StateWatch, Status, ANSWER_LIMIT};
use verdict::{Episode, Verdict};

/// The longest a recovery may take before the fault counts as not recovered. Generous: the
/// machine is shared, and start-up after a restart includes loading and mapping.
pub const RECOVERY_LIMIT: Duration = Duration::from_secs(20);

/// Polls this often while waiting for something.
const POLL: Duration = Duration::from_millis(20);

struct Soak {
    data: PathBuf,
    cfg: PathBuf,
    prefix: String,
    names: ServiceNames,
    node: iceoryx2::node::Node<ipc::Service>,
    ctl: Control,
    watch: StateWatch,
    daemon: Role,
    plant: Role,
    t0: Instant,
    loop_core: Option<usize>,
    tracked: leftovers::Tracked,
    v: Verdict,
    window: Option<windows::Open>,
    window_index: u32,
    last_sample: Instant,
}

/// One observation: a status answer (if the daemon answered) and the plant's flags.
#[derive(Clone, Debug)]
struct Obs {
    status: Option<Status>,
    /// Flags of every state seen since the previous observation.
    flags: u32,
    last_state: Option<StateSample>,
}

impl Soak {
    fn elapsed(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// One look at the system: a status (waiting at most `limit`), the plant's states, /proc.
    fn observe(&mut self, limit: Option<Duration>) -> Result<Obs> {
        if rt::signal::stop_requested() {
            bail!("interrupted");
        }
        self.daemon.check_alive()?;
        self.plant.check_alive()?;
        let status = match limit {
            Some(l) => self
                .ctl
                .batch(&self.node, &[(Op::Status, "")], l)
                .pop()
                .flatten()
                .and_then(|a| a.ok())
                .and_then(|b| Status::parse(&b).ok()),
            None => None,
        };
        if let Some(s) = &status {
            self.v.note_status(s);
        }
        let flags = self.watch.poll();
        if self.last_sample.elapsed() >= Duration::from_secs(1) {
            self.last_sample = Instant::now();
            self.daemon.sample();
            self.plant.sample();
        }
        Ok(Obs {
            status,
            flags,
            last_state: self.watch.last,
        })
    }

    /// Observes until `until`, calling `f` on each observation.
    fn watch_until(
        &mut self,
        until: Instant,
        limit: Option<Duration>,
        mut f: impl FnMut(&Obs),
    ) -> Result<()> {
        while Instant::now() < until {
            let o = self.observe(limit)?;
            f(&o);
            std::thread::sleep(POLL);
        }
        Ok(())
    }

    /// Waits for RUN (see the module docs) and for `extra` to hold; returns when it first did.
    fn wait_run(&mut self, mut extra: impl FnMut(&Status) -> bool) -> Result<Option<Instant>> {
        let until = Instant::now() + RECOVERY_LIMIT;
        let mut prev: Option<Status> = None;
        let mut seen = String::from("no status answered");
        while Instant::now() < until {
            let o = self.observe(Some(ANSWER_LIMIT))?;
            if let Some(s) = o.status {
                seen = format!(
                    "mode {}, {} params applied, μ {:?}, plant flags {:?}, fresh states {}",
                    s.mode,
                    s.params_applied,
                    s.mu,
                    o.last_state.map(|st| st.flags),
                    s.fresh
                );
                let plant_ok = o
                    .last_state
                    .is_some_and(|st| st.flags & (flags::COMMAND_TIMEOUT | flags::BRAKING) == 0)
                    && self
                        .watch
                        .last_at
                        .is_some_and(|t| t.elapsed() < Duration::from_millis(200));
                let moving = prev
                    .as_ref()
                    .is_some_and(|p| p.pid == s.pid && s.fresh > p.fresh);
                if s.mode == "Run" && moving && plant_ok && extra(&s) {
                    return Ok(Some(Instant::now()));
                }
                prev = Some(s);
            }
            std::thread::sleep(POLL);
        }
        // What kept it from RUN, for whoever reads a failed soak's output.
        eprintln!("chaosd-bench: soak: no recovery within {RECOVERY_LIMIT:?}; last seen: {seen}");
        Ok(None)
    }

    fn status_now(&mut self) -> Result<Status> {
        for _ in 0..5 {
            if let Some(s) = self.observe(Some(ANSWER_LIMIT))?.status {
                return Ok(s);
            }
        }
        bail!("the daemon did not answer status 5 times in a row")
    }

    fn note_resources(&mut self) {
        let mut pids = self.tracked.pids.clone();
        pids.extend(self.daemon.lives.iter().map(|l| l.pid));
        pids.extend(self.plant.lives.iter().map(|l| l.pid));
        pids.insert(std::process::id());
        self.tracked.pids = pids;
        self.tracked.note(&self.prefix);
    }

    // ---- recording windows ------------------------------------------------------------------

    fn open_window(&mut self) -> Result<()> {
        for _ in 0..5 {
            self.window_index += 1;
            let name = format!("soak-window-{}.csv", self.window_index);
            match windows::boundary(&mut self.ctl, &self.node, Op::RecordStart, &name)? {
                windows::Boundary::Done { at, .. } => {
                    self.window = Some(windows::Open { name, at });
                    return Ok(());
                }
                windows::Boundary::Straddled | windows::Boundary::NoAnswer => {
                    // Not exact: stop it (if it started) and throw it away.
                    let _ = self.ctl.one(&self.node, Op::RecordStop, "");
                    let _ = std::fs::remove_file(self.data.join(&name));
                }
            }
        }
        bail!("could not open a recording window at an exact tick in 5 tries")
    }

    fn close_window(&mut self) -> Result<()> {
        let Some(open) = self.window.take() else {
            return Ok(());
        };
        let path = self.data.join(&open.name);
        match windows::boundary(&mut self.ctl, &self.node, Op::RecordStop, "")? {
            windows::Boundary::Done { at, rows } => {
                let c = windows::check(&self.data, &open, &at, rows.unwrap_or(0))?;
                if c.lost() {
                    self.v.fail(format!(
                        "recording {} lost rows: {} in the file, {} by the daemon's count, {} states accepted over {} ticks",
                        path.display(), c.rows_file, c.rows_daemon, c.accepted, c.ticks
                    ));
                } else {
                    // Checked: its rows are all accounted for; keep the disk small.
                    let _ = std::fs::remove_file(&path);
                }
                self.v.windows.push(c);
            }
            _ => self.v.windows_unchecked += 1,
        }
        Ok(())
    }

    // ---- the faults ---------------------------------------------------------------------------

    fn episode(&mut self, f: &Fault) -> Result<Episode> {
        let before = self.status_now()?;
        let mut e = Episode::new(f.kind, self.elapsed());
        match f.kind {
            FaultKind::KillPlant => self.kill_plant(f, &before, &mut e)?,
            FaultKind::KillDaemon => self.kill_daemon(f, &mut e)?,
            FaultKind::StopPlant => self.stop_plant(f, &before, &mut e)?,
            FaultKind::StopDaemon => self.stop_daemon(f, &before, &mut e)?,
            FaultKind::Hog => self.hog(f, &before, &mut e)?,
            FaultKind::Rogue => self.rogue(f, &mut e)?,
            FaultKind::Burst => self.burst(f, &before, &mut e)?,
        }
        Ok(e)
    }

    fn kill_plant(&mut self, f: &Fault, before: &Status, e: &mut Episode) -> Result<()> {
        let t = Instant::now();
        self.plant.kill9();
        let mut seen = None;
        self.watch_until(t + f.duration, Some(POLL * 5), |o| {
            if seen.is_none() && o.status.as_ref().is_some_and(|s| s.holds > before.holds) {
                seen = Some(t.elapsed());
            }
        })?;
        e.detected = seen;
        self.plant.start(&[])?;
        let end = Instant::now();
        let restarts = before.plant_restarts;
        let holds = before.holds;
        let r = self.wait_run(|s| s.plant_restarts > restarts && s.holds > holds)?;
        if e.detected.is_none() && r.is_some() {
            e.detected = Some(t.elapsed()); // the HOLD count went up, seen only now
        }
        e.recovered = r.map(|at| at - end);
        Ok(())
    }

    fn kill_daemon(&mut self, f: &Fault, e: &mut Episode) -> Result<()> {
        if self.window.take().is_some() {
            self.v.windows_cut += 1;
        }
        let t = Instant::now();
        self.daemon.kill9();
        self.ctl.reset();
        let mut seen = None;
        self.watch_until(t + f.duration, None, |o| {
            if seen.is_none() && o.flags & flags::COMMAND_TIMEOUT != 0 {
                seen = Some(t.elapsed());
            }
        })?;
        e.detected = seen;
        let pid = self.daemon.start(&[])? as u64;
        let end = Instant::now();
        let r = self.wait_run(|s| s.pid == pid)?;
        e.recovered = r.map(|at| at - end);
        Ok(())
    }

    /// SIGSTOP `who`, watch for `pause`, SIGCONT whatever happened.
    fn stopped<T>(
        &mut self,
        daemon: bool,
        pause: Duration,
        body: impl FnOnce(&mut Self, Instant) -> Result<T>,
    ) -> Result<T> {
        let role = if daemon { &self.daemon } else { &self.plant };
        role.signal(libc::SIGSTOP)?;
        let t = Instant::now();
        let r = body(self, t + pause);
        let role = if daemon { &self.daemon } else { &self.plant };
        role.signal(libc::SIGCONT)?;
        r
    }

    fn stop_plant(&mut self, f: &Fault, before: &Status, e: &mut Episode) -> Result<()> {
        let t = Instant::now();
        let holds = before.holds;
        let seen = self.stopped(false, f.duration, |s, until| {
            let mut seen = None;
            s.watch_until(until, Some(POLL * 5), |o| {
                if seen.is_none() && o.status.as_ref().is_some_and(|s| s.holds > holds) {
                    seen = Some(t.elapsed());
                }
            })?;
            Ok(seen)
        })?;
        let end = Instant::now();
        e.detected = seen;
        let r = self.wait_run(|s| s.holds > holds)?;
        if e.detected.is_none() && r.is_some() {
            e.detected = Some(t.elapsed());
        }
        e.recovered = r.map(|at| at - end);
        Ok(())
    }

    fn stop_daemon(&mut self, f: &Fault, before: &Status, e: &mut Episode) -> Result<()> {
        let t = Instant::now();
        let plant_saw = self.stopped(true, f.duration, |s, until| {
            let mut seen = false;
            s.watch_until(until, None, |o| {
                seen |= o.flags & flags::COMMAND_TIMEOUT != 0;
            })?;
            Ok(seen)
        })?;
        let end = Instant::now();
        let overruns = before.overruns;
        let r = self.wait_run(|s| s.overruns > overruns)?;
        if r.is_some() {
            e.detected = Some(t.elapsed());
        }
        if plant_saw {
            e.note("plant timed out");
        }
        e.recovered = r.map(|at| at - end);
        Ok(())
    }

    fn hog(&mut self, f: &Fault, before: &Status, e: &mut Episode) -> Result<()> {
        let core = self.loop_core;
        let dur = f.duration;
        let t = Instant::now();
        let hog = std::thread::Builder::new()
            .name("soak-hog".into())
            .spawn(move || {
                let r = rt::setup::apply(rt::setup::RtRequest {
                    core,
                    priority: system::DAEMON_PRIORITY + 1,
                    lock_memory: false,
                });
                let until = Instant::now() + dur;
                let mut x = 0u64;
                while Instant::now() < until {
                    x = std::hint::black_box(x.wrapping_add(1));
                }
                r.sched_fifo.is_some() && r.pinned_core == core
            })?;
        let mut plant_saw = false;
        self.watch_until(t + dur, None, |o| {
            plant_saw |= o.flags & flags::COMMAND_TIMEOUT != 0;
        })?;
        let fifo = hog.join().map_err(|_| anyhow!("the hog thread panicked"))?;
        let end = Instant::now();
        e.detection_required = fifo;
        if !fifo {
            e.note("no SCHED_FIFO: normal priority");
        }
        let overruns = before.overruns;
        let mut harmed = false;
        let r = self.wait_run(|s| {
            harmed |= s.overruns > overruns;
            true
        })?;
        if harmed || plant_saw {
            e.detected = Some(t.elapsed());
        }
        if plant_saw {
            e.note("plant timed out");
        }
        e.recovered = r.map(|at| at - end);
        Ok(())
    }

    fn rogue(&mut self, f: &Fault, e: &mut Episode) -> Result<()> {
        let node = protocol::node("chaosd-soak-rogue")?;
        self.tracked.note(&self.prefix);
        let svc = protocol::open_state_service(&node, &self.names)?;
        if svc.publisher_builder().create().is_ok() {
            self.v.fail(
                "a second state publisher was accepted while the plant ran (max_publishers = 1)"
                    .into(),
            );
        } else {
            e.note("2nd publisher refused");
        }
        let Some(real) = self.watch.last else {
            bail!("no plant state seen before the rogue episode");
        };
        // The plant leaves cleanly: its summary must be written.
        let summary = self.data.join("plant-summary.json");
        let _ = std::fs::remove_file(&summary);
        self.plant.stop(Duration::from_secs(15))?;
        self.v.clean_stops += 1;
        if !summary.is_file() {
            self.v.fail(format!(
                "the plant stopped cleanly without writing {}",
                summary.display()
            ));
        }
        let hold = self.wait_hold()?;
        let publisher = {
            let until = Instant::now() + Duration::from_secs(5);
            loop {
                match svc.publisher_builder().create() {
                    Ok(p) => break p,
                    Err(err) if Instant::now() > until => {
                        bail!("the rogue could not publish after the plant left: {err:?}")
                    }
                    Err(_) => std::thread::sleep(POLL),
                }
            }
        };
        let t = Instant::now();
        let mut rng = Rng::new(f.seed);
        let mut sent = [0u64; 4];
        let mut next_look = t;
        let rejected = |s: &Status, h: &Status| {
            s.rejected_invalid > h.rejected_invalid
                && s.rejected_future > h.rejected_future
                && s.rejected_out_of_order > h.rejected_out_of_order
        };
        while t.elapsed() < f.duration {
            if Instant::now() >= next_look {
                next_look += Duration::from_millis(100);
                let o = self.observe(Some(Duration::from_millis(50)))?;
                if e.detected.is_none() && o.status.is_some_and(|s| rejected(&s, &hold)) {
                    e.detected = Some(t.elapsed());
                }
            }
            let k = rng.below(4);
            let mut s = real;
            s.stamp_ns = protocol::monotonic_ns();
            s.seq = real.seq + 1 + sent.iter().sum::<u64>();
            match k {
                0 => s.n = 99,                                     // malformed
                1 => s.qd[1] = f64::NAN,                           // not finite
                2 => s.stamp_ns += 5_000_000_000,                  // from the future
                _ => s.seq = real.seq.saturating_sub(1 + sent[3]), // an old sequence number
            }
            if publisher.send_copy(s).is_ok() {
                sent[k] += 1;
            }
            std::thread::sleep(Duration::from_millis(1));
            if rt::signal::stop_requested() {
                bail!("interrupted");
            }
        }
        drop(publisher);
        let end = Instant::now();
        std::thread::sleep(Duration::from_millis(50));
        let after = self.status_now()?;
        if after.fresh != hold.fresh {
            self.v.fail(format!(
                "the daemon accepted {} garbage states from the rogue publisher",
                after.fresh - hold.fresh
            ));
        }
        if e.detected.is_none() && rejected(&after, &hold) {
            e.detected = Some(end - t); // seen only after the rogue stopped
        }
        e.note(&format!(
            "sent {} bad-size, {} NaN, {} future, {} old-seq; rejected +{} invalid, +{} future, +{} out of order",
            sent[0],
            sent[1],
            sent[2],
            sent[3],
            after.rejected_invalid - hold.rejected_invalid,
            after.rejected_future - hold.rejected_future,
            after.rejected_out_of_order - hold.rejected_out_of_order
        ));
        drop(svc);
        drop(node);
        self.plant.start(&[])?;
        let restart = Instant::now();
        let restarts = after.plant_restarts;
        let r = self.wait_run(|s| s.plant_restarts > restarts)?;
        e.recovered = r.map(|at| at - restart);
        Ok(())
    }

    /// Waits until the daemon reports HOLD (after the plant left).
    fn wait_hold(&mut self) -> Result<Status> {
        let until = Instant::now() + RECOVERY_LIMIT;
        let mut last_mode = None;
        while Instant::now() < until {
            if let Some(s) = self.observe(Some(ANSWER_LIMIT))?.status {
                if s.mode == "Hold" {
                    return Ok(s);
                }
                last_mode = Some(s.mode);
            }
            std::thread::sleep(POLL);
        }
        match last_mode {
            Some(m) => {
                bail!("the daemon did not enter HOLD after the plant stopped (it stayed in {m})")
            }
            None => {
                bail!("the daemon did not enter HOLD after the plant stopped (no status answer)")
            }
        }
    }

    fn burst(&mut self, f: &Fault, before: &Status, e: &mut Episode) -> Result<()> {
        let mut rng = Rng::new(f.seed);
        // The μ values the last batch with an accepted `set` carried: six clients are in flight
        // at once, and the daemon may serve them in any order, so the one it applied last is
        // any of them (never one from an earlier batch: a batch waits for all its answers).
        let (mut answered, mut sets, mut last_mus) = (0usize, 0u64, Vec::<f64>::new());
        let t = Instant::now();
        let mut left = f.requests;
        while left > 0 {
            let n = left.min(6);
            left -= n;
            let reqs: Vec<(Op, String)> = (0..n)
                .map(|_| match rng.below(10) {
                    0..=5 => (Op::Status, String::new()),
                    6 | 7 => (Op::GetConfig, String::new()),
                    _ => (Op::Set, format!("mu {:.3}", 0.05 + 0.25 * rng.unit())),
                })
                .collect();
            let refs: Vec<(Op, &str)> = reqs.iter().map(|(o, a)| (*o, a.as_str())).collect();
            let answers = self.ctl.batch(&self.node, &refs, ANSWER_LIMIT);
            let mut batch_mus = Vec::new();
            for ((op, args), a) in reqs.iter().zip(answers) {
                match a {
                    Some(Ok(_)) => {
                        answered += 1;
                        if *op == Op::Set {
                            sets += 1;
                            batch_mus.extend(set_mu(args));
                        }
                    }
                    // "try again": the loop had not taken the previous change; still an answer.
                    Some(Err(_)) => answered += 1,
                    None => {}
                }
            }
            if !batch_mus.is_empty() {
                last_mus = batch_mus;
            }
            self.observe(None)?;
        }
        let end = Instant::now();
        if answered == f.requests {
            e.detected = Some(t.elapsed());
        }
        e.note(&format!(
            "{answered}/{} answered, {sets} sets accepted; the last batch of them asked μ ∈ {:?}",
            f.requests, last_mus
        ));
        let applied = before.params_applied;
        let r =
            self.wait_run(|s| s.params_applied == applied + sets && mu_is_one_of(s.mu, &last_mus))?;
        e.recovered = r.map(|at| at - end);
        Ok(())
    }

    // ---- start and end ------------------------------------------------------------------------

    fn start(&mut self) -> Result<()> {
        self.daemon.start(&["--fresh"])?;
        // The daemon first, so the first window opens before any state arrives.
        let until = Instant::now() + RECOVERY_LIMIT;
        while self.observe(Some(ANSWER_LIMIT))?.status.is_none() {
            if Instant::now() > until {
                bail!("the daemon never answered status");
            }
            std::thread::sleep(POLL);
        }
        self.open_window()?;
        self.plant.start(&[])?;
        if self.wait_run(|_| true)?.is_none() {
            bail!("the system never reached RUN");
        }
        self.note_resources();
        Ok(())
    }

    /// The clean stop at the end and its files.
    fn finish(&mut self) -> Result<()> {
        self.close_window()?;
        let dsum = self.data.join(daemon::telemetry::SUMMARY_FILE);
        let psum = self.data.join("plant-summary.json");
        let _ = std::fs::remove_file(&dsum);
        let _ = std::fs::remove_file(&psum);
        self.note_resources();
        let r1 = self.daemon.stop(Duration::from_secs(15));
        let r2 = self.plant.stop(Duration::from_secs(15));
        r1?;
        r2?;
        self.v.clean_stops += 2;
        match read_json(&dsum) {
            Ok(d) => {
                let ticks = d["counters"]["ticks"].as_u64().unwrap_or(0);
                let records = d["lateness"]["count"].as_u64().unwrap_or(0);
                let dropped = d["counters"]["telemetry_dropped"].as_u64().unwrap_or(0);
                self.v.final_ticks = Some((ticks, records));
                if ticks == 0 || records != ticks || dropped != 0 {
                    self.v.fail(format!(
                        "final daemon summary: {records} records reached the reporter of {ticks} ticks, {dropped} dropped"
                    ));
                }
            }
            Err(e) => self
                .v
                .fail(format!("no daemon summary after the clean stop: {e:#}")),
        }
        if let Err(e) = read_json(&psum) {
            self.v
                .fail(format!("no plant summary after the clean stop: {e:#}"));
        }
        Ok(())
    }
}

/// Every /proc sample, one row each: process, lifetime, pid, seconds since the start, RSS (kB),
/// open fds. The rate in the verdict comes from these; a long run's file shows the trend.
fn resources_csv(t0: Instant, roles: &[&Role]) -> String {
    let mut out = String::from("process,lifetime,pid,t_s,rss_kb,fds\n");
    for r in roles {
        for (i, l) in r.lives.iter().enumerate() {
            for x in &l.samples {
                out.push_str(&format!(
                    "{},{},{},{:.1},{},{}\n",
                    r.name,
                    i + 1,
                    l.pid,
                    (x.at - t0).as_secs_f64(),
                    x.rss_kb,
                    x.fds
                ));
            }
        }
    }
    out
}

/// The μ a burst's `set mu X` asked for.
fn set_mu(args: &str) -> Option<f64> {
    args.strip_prefix("mu ")?.trim().parse().ok()
}

/// Whether the daemon's μ is one the last batch of accepted sets asked for (any μ when the
/// burst accepted none).
fn mu_is_one_of(mu: Option<f64>, asked: &[f64]) -> bool {
    asked.is_empty() || mu.is_some_and(|x| asked.iter().any(|m| (x - m).abs() < 1e-9))
}

fn read_json(p: &Path) -> Result<serde_json::Value> {
    let text =
        std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not JSON", p.display()))
}

/// Runs the soak; the report (with the verdict) is returned, or printed and an error returned
/// when the verdict is a failure.
pub fn run(opts: &Options, out: &Path, command: &str) -> Result<crate::report::Output> {
    opts.validate()?;
    let report = crate::report::Report::new(out, "soak")?;
    let dir = report.dir.clone();
    let data = dir.join("system");
    let _ = std::fs::remove_dir_all(&data);
    std::fs::create_dir_all(&data)?;
    let ns = crate::latency::unique_namespace("soak");
    let names = ServiceNames::new(&ns).map_err(|e| anyhow!("namespace {ns:?}: {e}"))?;
    let cfg = dir.join("config.toml");
    std::fs::write(&cfg, system::config_text(&ns, &data))?;
    let cfg_s = cfg.to_string_lossy().to_string();
    let node = protocol::node("chaosd-soak")?;
    let watch = StateWatch::new(&node, &names)?;
    let plan = schedule::plan(
        opts.seed,
        Duration::from_secs_f64(opts.seconds),
        &opts.faults,
    );
    let mut s = Soak {
        data,
        cfg: cfg.clone(),
        prefix: names.to_string(),
        names: names.clone(),
        ctl: Control::new(&names),
        node,
        watch,
        daemon: Role::new(
            "chaosd",
            system::sibling("chaosd")?,
            vec!["run".into(), "--config".into(), cfg_s.clone()],
            &dir,
        ),
        plant: Role::new(
            "chaosd-plant",
            system::sibling("chaosd-plant")?,
            vec!["--config".into(), cfg_s],
            &dir,
        ),
        t0: Instant::now(),
        loop_core: daemon::config::DaemonConfig::default().core,
        tracked: leftovers::Tracked {
            since_s: leftovers::monotonic_s(),
            ..Default::default()
        },
        v: Verdict::new(opts, &ns),
        window: None,
        window_index: 0,
        last_sample: Instant::now(),
    };
    let result = drive(&mut s, &plan);
    // Whatever happened: nothing may keep running.
    let _ = s.daemon.signal(libc::SIGCONT);
    let _ = s.plant.signal(libc::SIGCONT);
    if let Err(e) = &result {
        s.v.fail(format!("the soak stopped early: {e:#}"));
        s.daemon.kill9();
        s.plant.kill9();
    }
    s.v.lives = (
        verdict::Lives::of(&s.daemon.lives),
        verdict::Lives::of(&s.plant.lives),
    );
    let csv = report.path("resources.csv");
    if let Err(e) = std::fs::write(&csv, resources_csv(s.t0, &[&s.daemon, &s.plant])) {
        s.v.fail(format!("cannot write {}: {e}", csv.display()));
    }
    s.v.seconds = s.elapsed();
    let Soak {
        node,
        ctl,
        watch,
        tracked,
        prefix,
        cfg,
        mut v,
        ..
    } = s;
    drop(ctl);
    drop(watch);
    drop(node);
    let left = tracked.leftovers(&prefix, &cfg)?;
    v.leftovers = left;
    v.tracked = (tracked.services.len(), tracked.nodes.len());
    if tracked.layout_mismatches > 0 {
        v.fail(format!(
            "{} iceoryx2 node ids do not decode to their pid: the file check cannot attribute files",
            tracked.layout_mismatches
        ));
    }
    let text = v.render(command);
    let mut report = report;
    report.files.push(report.path("resources.csv"));
    report.run_detail(format!("seed {}, {:.0} s", opts.seed, opts.seconds));
    report.push_tables(
        &text,
        &[names::SOAK_FAULTS, names::SOAK_PROCESSES, names::SOAK_DATA],
    )?;
    let output = report.finish()?;
    if v.passed() {
        Ok(output)
    } else {
        print!("{}", output.text);
        bail!("soak verdict: FAIL ({})", v.failures.join("; "))
    }
}

fn drive(s: &mut Soak, plan: &[Fault]) -> Result<()> {
    s.start()?;
    let phase = Instant::now();
    for f in plan {
        let at = phase + f.at;
        // Quiet until the planned time (or at once, if the previous episode ran late).
        s.watch_until(at, Some(ANSWER_LIMIT), |_| {})?;
        let e = s.episode(f)?;
        let ok = e.recovered.is_some();
        s.v.episodes.push(e);
        if !ok {
            bail!(
                "{} did not recover within {RECOVERY_LIMIT:?}",
                f.kind.label()
            );
        }
        s.note_resources();
        s.close_window()?;
        s.open_window()?;
    }
    let end = phase + Duration::from_secs_f64(s.v.planned_seconds);
    s.watch_until(
        end.max(Instant::now() + schedule::TAIL),
        Some(ANSWER_LIMIT),
        |_| {},
    )?;
    if s.wait_run(|_| true)?.is_none() {
        bail!("the system was not in RUN at the end");
    }
    s.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burst_accepts_the_mu_of_any_set_in_its_last_batch_and_no_other() {
        assert_eq!(set_mu("mu 0.252"), Some(0.252));
        assert_eq!(set_mu("tau 1.0"), None);
        assert_eq!(set_mu("mu x"), None);
        let asked = [0.252, 0.113];
        assert!(mu_is_one_of(Some(0.113), &asked));
        assert!(mu_is_one_of(Some(0.252), &asked));
        assert!(!mu_is_one_of(Some(0.2), &asked));
        assert!(!mu_is_one_of(None, &asked));
        assert!(mu_is_one_of(None, &[]));
    }
}
