//! Deterministic record and replay (`chaosd run --record NAME`, `chaosctl replay RECORDING`).
//!
//! The controller is a pure function of its inputs: the configuration it starts from, the
//! sample handed to each tick, the tick's clock, and the changes the control service applies
//! between ticks. A replay recording holds exactly those, bit for bit, from the daemon's first
//! tick, with the command each tick produced. [`replay`] feeds them through the same
//! [`Controller`] the loop runs and compares every command field by field, bit for bit (after
//! copper-rs's determinism test: run A == replay of A).
//!
//! The reporter thread writes the file ([`ReplayLog`]); the loop only hands it the `Copy` tick
//! record it already sends. The file is owner-only and stays in the output directory
//! ([`crate::recording_files::resolve`]).
//!
//! A recording is MCAP (`--record run.mcap`, or any name not ending in `.replay`): the text
//! below, one message a tick on its `/chaosd/replay` channel, beside every channel of
//! [`crate::view`], so the run that replays bit for bit also opens in Foxglove. A name ending in
//! `.replay` writes the text alone; [`replay`] reads both.
//!
//! # Format (text, version 4; every `f64` as the 16 hex digits of its bits)
//!
//! ```text
//! chaosd-replay 4
//! settings n=3 rate_hz=<f64> first_order_hold=1 hold_after=5 stale_ns=5000000 \
//!          future_slack_ns=1000000 daemon_id=<u64> t_start=<f64> fault=0 handshake=1 \
//!          [arm=<u64 hex>]
//! config <k>                  the running configuration as TOML, k lines follow
//! P <tick> <k>                a parameter block taking effect before <tick>: its config, k lines
//! R <tick>                    an operator's resume taking effect before <tick>
//! H <tick> <plant_id> <0|1>   the handshake's verdict on a plant start, before <tick>
//! S <tick> 0                  steering stops, before <tick>
//! S <tick> 1 <t0> <period> <kp> <kd> <k> <q…>   steering onto a planned cycle of k postures
//!                             (3 joints each on the planar arm, MAX_JOINTS on a robot's
//!                             chain), before <tick> (`crate::replay_steer`)
//! B <tick> <0|1>              blocked with the hold action begins (1) or ends (0), before <tick>
//! T <tick> <now_ns> <state> <command>
//! G <tick> <missing>          <missing> records never reached the reporter: the recording ends
//! ```
//! (the `settings` line is one line). `arm` is a robot's fingerprint (`System::identity`: its
//! chain's every number), present when the config has a `[robot]`: a replay loads the robot the
//! config names and refuses one whose numbers changed since. `<state>` is `-` (nothing
//! received) or `seq,stamp_ns,plant_id,n,flags,phi,q[0..12],qd[0..12]`; `<command>` is `-` (none
//! sent) or `seq,state_seq,state_stamp_ns,stamp_ns,daemon_id,mode,n,interface,qdd[0..12],
//! qddd[0..12],q[0..12],qd[0..12],tau[0..12]` (one field list): every array whole, `MAX_JOINTS`
//! entries, so that a position, velocity or torque command is compared whole. Integers are
//! decimal. Ticks count from 0 at the daemon's start.
//!
//! Older recordings still replay: version 3 is the same with arrays (and steering postures) of
//! 7 entries, before the joint capacity became 12; version 2 is version 3 without `arm` and with
//! the command's `interface`, `q`, `qd` and `tau` left out (recordings of the planar arm in
//! acceleration mode), its commands compared on what they hold. Version 1 had arrays of 6
//! entries (before the capacity became 7); it is refused by name.

use crate::controller::{Applied, Controller, ControllerSettings};
use crate::telemetry::TickRecord;
use anyhow::{anyhow, bail, Result};
use control::System;
use protocol::{CommandSample, StateSample, MAX_JOINTS};
use std::collections::VecDeque;
use std::fmt::Write as _;
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};

const MAGIC: &str = "chaosd-replay 4";
/// The header of format 3 (arrays of 7 entries).
const MAGIC_V3: &str = "chaosd-replay 3";
/// The header of format 2 (arrays of 7, commands without interface, references and torques).
const MAGIC_V2: &str = "chaosd-replay 2";
/// The entries of every per-joint array in formats 2 and 3 (the joint capacity then).
const OLD_WIDTH: usize = 7;
/// The header of format 1 (arrays of 6 entries), which this build cannot read.
const MAGIC_V1: &str = "chaosd-replay 1";
/// No line of a valid recording comes near this.
const MAX_LINE: u64 = 16 * 1024;

/// The running configuration as the recording stores it (without `[daemon]` and `[plant]`).
pub fn system_toml(system: &System) -> String {
    let mut s = system.clone();
    let (daemon, plant) = s.tables_mut();
    *daemon = None;
    *plant = None;
    s.to_toml()
}

/// What the loop is sent with data a replay needs, in the order sent.
enum Announced {
    /// A configuration, as [`system_toml`] writes it.
    Config(String),
    /// A steering handover, as [`crate::replay_steer::line`] writes it.
    Steer(String),
}

/// Where a replay recording goes.
enum Out {
    /// The text format itself (a name ending in `.replay`).
    Text(std::io::BufWriter<std::fs::File>),
    /// An MCAP recording whose `/chaosd/replay` channel holds the same text, one message a tick,
    /// beside every channel `chaosctl record` writes (any other name). The header waits for the
    /// first tick, so that every channel's times run forwards.
    Mcap {
        rec: Box<crate::mcap_recording::McapRecording>,
        header: Option<String>,
    },
}

/// An open replay recording, written by the reporter thread.
pub struct ReplayLog {
    pub path: PathBuf,
    file: Out,
    next_tick: u64,
    /// Configs and steering handed to the loop and not yet seen applied, oldest first (the
    /// loop takes requests in the order they were sent).
    pending: VecDeque<Announced>,
    /// Why the recording stopped, once it has.
    pub stopped: Option<String>,
    /// Bytes written so far, and the most it may grow to (`daemon.record_max_bytes`).
    written: u64,
    max_bytes: u64,
}

impl ReplayLog {
    /// Creates `name` in `out_dir` and writes the header: what the controller starts from.
    pub fn create(
        out_dir: &Path,
        name: &str,
        system: &System,
        settings: &ControllerSettings,
        start_in_fault: bool,
        handshake: bool,
    ) -> Result<Self, String> {
        let path = crate::recording_files::resolve(out_dir, name, "mcap")?;
        let s = settings;
        let config = system_toml(system);
        let arm = system
            .identity()
            .map_or(String::new(), |id| format!(" arm={:016x}", id.fingerprint));
        let header = format!(
            "{MAGIC}\nsettings n={} rate_hz={:016x} first_order_hold={} hold_after={} stale_ns={} future_slack_ns={} daemon_id={} t_start={:016x} fault={} handshake={}{arm}\nconfig {}\n{config}",
            system.n(),
            s.rate_hz.to_bits(),
            u8::from(s.first_order_hold),
            s.hold_after,
            s.stale_ns,
            s.future_slack_ns,
            s.daemon_id,
            s.t_start.to_bits(),
            u8::from(start_in_fault),
            u8::from(handshake),
            config.lines().count(),
        );
        let written = header.len() as u64;
        let file = if path.extension().is_some_and(|e| e == "replay") {
            let cannot = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
            let mut file = crate::recording_files::open(&path).map_err(cannot)?;
            file.write_all(header.as_bytes()).map_err(cannot)?;
            Out::Text(file)
        } else {
            let name = path
                .strip_prefix(out_dir)
                .unwrap_or(&path)
                .to_string_lossy();
            let no_limit = crate::rotate::Limit {
                max_bytes: None,
                keep: 0,
            };
            let rec = crate::mcap_recording::McapRecording::start(
                out_dir, &name, system, s.rate_hz, no_limit,
            )?;
            Out::Mcap {
                rec: Box::new(rec),
                header: Some(header),
            }
        };
        Ok(Self {
            path,
            file,
            next_tick: 0,
            pending: VecDeque::new(),
            stopped: None,
            written,
            max_bytes: u64::MAX,
        })
    }

    /// Caps the file at `max_bytes`. A replay recording cannot rotate (a replay starts from the
    /// first tick), so at the cap it stops, says so, and stays a valid recording of every tick
    /// up to there.
    pub fn with_max_bytes(mut self, max_bytes: u64) -> Self {
        self.max_bytes = max_bytes;
        self
    }

    /// A configuration the control service has just sent to the loop.
    pub fn committed(&mut self, system: &System) {
        self.pending
            .push_back(Announced::Config(system_toml(system)));
    }

    /// A steering handover the planner has just sent to the loop.
    pub fn steered(&mut self, steer: Option<&control::steer::Steering>) {
        self.pending
            .push_back(Announced::Steer(crate::replay_steer::line(steer)));
    }

    /// The MCAP recording this writes into, if it is one (for events and scene changes).
    pub fn mcap(&mut self) -> Option<&mut crate::mcap_recording::McapRecording> {
        match &mut self.file {
            Out::Mcap { rec, .. } => Some(rec),
            Out::Text(_) => None,
        }
    }

    /// Appends one tick (`ctx`: what an MCAP recording's other channels show with it). After a
    /// gap or a write error the recording stops (and says why).
    pub fn tick(&mut self, r: &TickRecord, ctx: crate::view::TickContext) {
        if self.stopped.is_some() {
            return;
        }
        if let Err(e) = self.write_tick(r, ctx) {
            self.stopped = Some(format!(
                "replay recording {} stopped at tick {}: {e}",
                self.path.display(),
                self.next_tick
            ));
            if let Out::Text(f) = &mut self.file {
                let _ = f.flush();
            }
        }
    }

    /// Writes one tick's text (and, into MCAP, its other channels).
    fn emit(
        &mut self,
        r: &TickRecord,
        ctx: crate::view::TickContext,
        text: &str,
    ) -> std::io::Result<()> {
        match &mut self.file {
            Out::Text(f) => f.write_all(text.as_bytes()),
            Out::Mcap { rec, header } => {
                let mut done = match header.take() {
                    Some(h) => rec.replay_text(r.now_ns, &(h + text)),
                    None => rec.replay_text(r.now_ns, text),
                };
                if let (Ok(()), Some(st), true) = (&done, &r.state, r.ran_law) {
                    done = rec.tick(r, st, ctx);
                }
                done.map_err(std::io::Error::other)
            }
        }
    }

    fn write_tick(&mut self, r: &TickRecord, ctx: crate::view::TickContext) -> std::io::Result<()> {
        let tick = r.counters.ticks.saturating_sub(1);
        if tick != self.next_tick {
            let gap = format!("G {} {}\n", self.next_tick, tick.abs_diff(self.next_tick));
            self.emit(r, ctx, &gap)?;
            return Err(std::io::Error::other(
                "tick records were lost (the telemetry queue was full)",
            ));
        }
        let mut out = String::with_capacity(1400);
        match r.applied {
            Some(Applied::Params) => {
                let Some(Announced::Config(cfg)) = self.pending.pop_front() else {
                    return Err(std::io::Error::other(
                        "a parameter change reached the loop unannounced",
                    ));
                };
                let _ = write!(out, "P {tick} {}\n{cfg}", cfg.lines().count());
            }
            Some(Applied::Steer) => {
                let Some(Announced::Steer(line)) = self.pending.pop_front() else {
                    return Err(std::io::Error::other(
                        "a steering handover reached the loop unannounced",
                    ));
                };
                let _ = writeln!(out, "S {tick} {line}");
            }
            Some(Applied::BlockedHold(hold)) => {
                let _ = writeln!(out, "B {tick} {}", u8::from(hold));
            }
            Some(Applied::Resume) => {
                let _ = writeln!(out, "R {tick}");
            }
            Some(Applied::Plant { plant_id, agreed }) => {
                let _ = writeln!(out, "H {tick} {plant_id} {}", u8::from(agreed));
            }
            None => {}
        }
        let _ = write!(out, "T {tick} {} ", r.now_ns);
        match &r.state {
            Some(s) => state_fields(&mut out, s),
            None => out.push('-'),
        }
        out.push(' ');
        match &r.command {
            Some(c) => command_fields(&mut out, c),
            None => out.push('-'),
        }
        out.push('\n');
        let written = match &self.file {
            Out::Mcap { rec, .. } => rec.bytes(),
            Out::Text(_) => self.written,
        };
        if written.saturating_add(out.len() as u64) > self.max_bytes {
            return Err(std::io::Error::other(format!(
                "it reached daemon.record_max_bytes = {} bytes (a replay recording is one file \
                 from the first tick: it stops rather than rotates); it replays up to here",
                self.max_bytes
            )));
        }
        self.emit(r, ctx, &out)?;
        self.written += out.len() as u64;
        self.next_tick += 1;
        Ok(())
    }

    /// Flushes and closes the file.
    pub fn finish(self) -> Result<PathBuf, String> {
        let cannot = |e: String| format!("cannot finish {}: {e}", self.path.display());
        match self.file {
            Out::Text(mut f) => f.flush().map_err(|e| cannot(e.to_string()))?,
            Out::Mcap { rec, .. } => {
                rec.finish().map_err(cannot)?;
            }
        }
        match self.stopped {
            Some(why) => Err(why),
            None => Ok(self.path),
        }
    }
}

fn state_fields(out: &mut String, s: &StateSample) {
    let _ = write!(
        out,
        "{},{},{},{},{},{:016x}",
        s.seq,
        s.stamp_ns,
        s.plant_id,
        s.n,
        s.flags,
        s.phi.to_bits()
    );
    for v in s.q.iter().chain(&s.qd) {
        let _ = write!(out, ",{:016x}", v.to_bits());
    }
}

fn command_fields(out: &mut String, c: &CommandSample) {
    let _ = write!(
        out,
        "{},{},{},{},{},{},{},{}",
        c.seq, c.state_seq, c.state_stamp_ns, c.stamp_ns, c.daemon_id, c.mode, c.n, c.interface
    );
    for v in c
        .qdd
        .iter()
        .chain(&c.qddd)
        .chain(&c.q)
        .chain(&c.qd)
        .chain(&c.tau)
    {
        let _ = write!(out, ",{:016x}", v.to_bits());
    }
}

/// Comma-separated fields of one sample, read in order.
struct Fields<'a> {
    it: std::str::Split<'a, char>,
    what: &'static str,
}

impl<'a> Fields<'a> {
    fn new(text: &'a str, what: &'static str) -> Self {
        Self {
            it: text.split(','),
            what,
        }
    }
    fn next(&mut self) -> Result<&'a str> {
        self.it
            .next()
            .ok_or_else(|| anyhow!("the {} has too few fields", self.what))
    }
    fn int<T: std::str::FromStr>(&mut self) -> Result<T> {
        let f = self.next()?;
        f.parse()
            .map_err(|_| anyhow!("{} field {:?} is not an integer", self.what, excerpt(f)))
    }
    fn f64(&mut self) -> Result<f64> {
        let f = self.next()?;
        if f.len() != 16 {
            bail!(
                "{} field {:?} is not 16 hex digits of an f64",
                self.what,
                excerpt(f)
            );
        }
        u64::from_str_radix(f, 16)
            .map(f64::from_bits)
            .map_err(|_| anyhow!("{} field {:?} is not hex", self.what, excerpt(f)))
    }
    fn end(mut self) -> Result<()> {
        match self.it.next() {
            None => Ok(()),
            Some(_) => bail!("the {} has too many fields", self.what),
        }
    }
}

fn excerpt(s: &str) -> String {
    s.chars().take(40).collect()
}

/// What a recording's format holds: every command field (`whole`, formats 3 and 4) or the
/// acceleration and its rate (format 2), and how many entries each per-joint array has.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Layout {
    whole: bool,
    width: usize,
}

fn parse_state(text: &str, width: usize) -> Result<Option<StateSample>> {
    if text == "-" {
        return Ok(None);
    }
    let mut f = Fields::new(text, "state");
    let mut s = StateSample {
        seq: f.int()?,
        stamp_ns: f.int()?,
        plant_id: f.int()?,
        n: f.int()?,
        flags: f.int()?,
        phi: f.f64()?,
        ..StateSample::default()
    };
    for v in s.q[..width].iter_mut().chain(s.qd[..width].iter_mut()) {
        *v = f.f64()?;
    }
    f.end()?;
    Ok(Some(s))
}

/// A command of the recording's [`Layout`]; the entries past its width stay zero.
fn parse_command(text: &str, layout: Layout) -> Result<Option<CommandSample>> {
    if text == "-" {
        return Ok(None);
    }
    let mut f = Fields::new(text, "command");
    let mut c = CommandSample {
        seq: f.int()?,
        state_seq: f.int()?,
        state_stamp_ns: f.int()?,
        stamp_ns: f.int()?,
        daemon_id: f.int()?,
        mode: f.int()?,
        n: f.int()?,
        ..CommandSample::default()
    };
    let w = layout.width;
    if layout.whole {
        c.interface = f.int()?;
        let arrays = c.q[..w]
            .iter_mut()
            .chain(c.qd[..w].iter_mut())
            .chain(c.tau[..w].iter_mut());
        for v in c.qdd[..w]
            .iter_mut()
            .chain(c.qddd[..w].iter_mut())
            .chain(arrays)
        {
            *v = f.f64()?;
        }
    } else {
        for v in c.qdd[..w].iter_mut().chain(c.qddd[..w].iter_mut()) {
            *v = f.f64()?;
        }
    }
    f.end()?;
    Ok(Some(c))
}

/// The first command that differs: which tick, which field, both values.
#[derive(Clone, Debug, PartialEq)]
pub struct Mismatch {
    pub tick: u64,
    pub field: String,
    pub recorded: String,
    pub replayed: String,
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "first mismatch at tick {}: {} recorded {}, replayed {}",
            self.tick, self.field, self.recorded, self.replayed
        )
    }
}

/// What a replay found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReplayReport {
    pub ticks: u64,
    /// Ticks whose command (or absence of one) replayed bit for bit.
    pub matched: u64,
    pub commands: u64,
    pub param_changes: u64,
    pub resumes: u64,
    pub first_mismatch: Option<Mismatch>,
}

impl ReplayReport {
    pub fn all_matched(&self) -> bool {
        self.matched == self.ticks && self.first_mismatch.is_none()
    }
}

impl std::fmt::Display for ReplayReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} ticks replayed bit-identically ({} commands, {} parameter changes, {} resumes)",
            self.matched, self.ticks, self.commands, self.param_changes, self.resumes
        )?;
        if let Some(m) = &self.first_mismatch {
            write!(f, "\n{m}")?;
        }
        Ok(())
    }
}

fn float(v: f64) -> String {
    format!("{v:e} (bits 0x{:016x})", v.to_bits())
}

/// The first field where the recorded command and the replayed one differ (`whole`: a format-3
/// or 4 recording, which holds every field; format 2 holds the acceleration and its rate).
fn compare(
    tick: u64,
    rec: Option<&CommandSample>,
    rep: Option<&CommandSample>,
    whole: bool,
) -> Option<Mismatch> {
    let m = |field: &str, recorded: String, replayed: String| {
        Some(Mismatch {
            tick,
            field: field.into(),
            recorded,
            replayed,
        })
    };
    let (a, b) = match (rec, rep) {
        (None, None) => return None,
        (Some(_), None) => return m("command", "one".into(), "none".into()),
        (None, Some(_)) => return m("command", "none".into(), "one".into()),
        (Some(a), Some(b)) => (a, b),
    };
    for (name, x, y) in [
        ("seq", a.seq, b.seq),
        ("state_seq", a.state_seq, b.state_seq),
        ("state_stamp_ns", a.state_stamp_ns, b.state_stamp_ns),
        ("stamp_ns", a.stamp_ns, b.stamp_ns),
        ("daemon_id", a.daemon_id, b.daemon_id),
        ("mode", a.mode.into(), b.mode.into()),
        ("n", a.n.into(), b.n.into()),
        ("interface", a.interface.into(), b.interface.into()),
    ] {
        if x != y && (whole || name != "interface") {
            return m(&format!("command.{name}"), x.to_string(), y.to_string());
        }
    }
    let arrays = [
        ("qdd", &a.qdd, &b.qdd),
        ("qddd", &a.qddd, &b.qddd),
        ("q", &a.q, &b.q),
        ("qd", &a.qd, &b.qd),
        ("tau", &a.tau, &b.tau),
    ];
    for (name, xs, ys) in &arrays[..if whole { 5 } else { 2 }] {
        for (i, (x, y)) in xs.iter().zip(ys.iter()).enumerate() {
            if x.to_bits() != y.to_bits() {
                return m(&format!("command.{name}[{i}]"), float(*x), float(*y));
            }
        }
    }
    None
}

/// Reads lines with a length limit, numbering them, and refusing a truncated last line.
struct Lines<R> {
    r: R,
    no: u64,
    buf: String,
}

impl<R: BufRead> Lines<R> {
    /// The next line without its newline; `Ok(None)` at the end.
    fn next(&mut self) -> Result<Option<&str>> {
        self.buf.clear();
        let got = (&mut self.r)
            .take(MAX_LINE)
            .read_line(&mut self.buf)
            .map_err(|e| anyhow!("line {}: {e}", self.no + 1))?;
        if got == 0 {
            return Ok(None);
        }
        self.no += 1;
        match self.buf.strip_suffix('\n') {
            Some(l) => Ok(Some(l)),
            None if got as u64 >= MAX_LINE => {
                bail!("line {}: longer than {MAX_LINE} bytes", self.no)
            }
            None => bail!("line {}: truncated (the recording ends mid-line)", self.no),
        }
    }

    fn block(&mut self, k: usize) -> Result<String> {
        let mut text = String::new();
        for _ in 0..k {
            let l = self
                .next()?
                .ok_or_else(|| anyhow!("the recording ends inside a config block"))?;
            text.push_str(l);
            text.push('\n');
        }
        Ok(text)
    }
}

/// A recorded configuration; a robot's chain is `chain` when given (a parameter change keeps the
/// robot the header loaded), else loaded from what the config names.
fn parse_system(text: &str, chain: Option<&control::model::Chain>) -> Result<System> {
    let parsed = match chain {
        Some(chain) => System::parse(text, &|_, _, _| Ok(chain.clone())),
        None => rt::robot::parse(text),
    };
    parsed.map_err(|e| anyhow!("a recorded config does not parse: {e}"))
}

/// One `key=value` of the settings line.
fn setting<'a>(fields: &mut impl Iterator<Item = &'a str>, key: &str) -> Result<&'a str> {
    let f = fields
        .next()
        .ok_or_else(|| anyhow!("the settings line has no {key}"))?;
    f.strip_prefix(key)
        .and_then(|v| v.strip_prefix('='))
        .ok_or_else(|| {
            anyhow!(
                "the settings line has {:?} where {key}= belongs",
                excerpt(f)
            )
        })
}

fn int<T: std::str::FromStr>(v: &str, what: &str) -> Result<T> {
    v.parse()
        .map_err(|_| anyhow!("{what} = {:?} is not a valid integer", excerpt(v)))
}

fn bits(v: &str, what: &str) -> Result<f64> {
    if v.len() != 16 {
        bail!("{what} = {:?} is not 16 hex digits", excerpt(v));
    }
    u64::from_str_radix(v, 16)
        .map(f64::from_bits)
        .map_err(|_| anyhow!("{what} = {:?} is not hex", excerpt(v)))
}

struct Header {
    n: usize,
    settings: ControllerSettings,
    start_in_fault: bool,
    handshake: bool,
    system: System,
    layout: Layout,
}

fn header<R: BufRead>(lines: &mut Lines<R>) -> Result<Header> {
    let (whole, width) = match lines.next()? {
        Some(MAGIC) => (true, MAX_JOINTS),
        Some(MAGIC_V3) => (true, OLD_WIDTH),
        Some(MAGIC_V2) => (false, OLD_WIDTH),
        Some(MAGIC_V1) => bail!("a replay recording of format 1 (6-joint arrays, chaosd before wire version 5); this build reads formats 2 to 4: replay it with the build that recorded it"),
        _ => bail!("not a chaosd replay recording (the first line is not {MAGIC:?}; `chaosctl record` CSV files cannot be replayed)"),
    };
    let line = lines
        .next()?
        .ok_or_else(|| anyhow!("the recording ends after its first line"))?
        .to_string();
    let mut f = line
        .strip_prefix("settings ")
        .ok_or_else(|| anyhow!("line 2 is not the settings line"))?
        .split(' ');
    let n: usize = int(setting(&mut f, "n")?, "n")?;
    if !(protocol::MIN_JOINTS..=width).contains(&n) {
        bail!("the settings say n = {n}: not an arm size chaosd runs (or recorded in this format)");
    }
    let settings = ControllerSettings {
        rate_hz: bits(setting(&mut f, "rate_hz")?, "rate_hz")?,
        first_order_hold: int::<u8>(setting(&mut f, "first_order_hold")?, "first_order_hold")? != 0,
        hold_after: int(setting(&mut f, "hold_after")?, "hold_after")?,
        stale_ns: int(setting(&mut f, "stale_ns")?, "stale_ns")?,
        future_slack_ns: int(setting(&mut f, "future_slack_ns")?, "future_slack_ns")?,
        daemon_id: int(setting(&mut f, "daemon_id")?, "daemon_id")?,
        t_start: bits(setting(&mut f, "t_start")?, "t_start")?,
    };
    let start_in_fault = int::<u8>(setting(&mut f, "fault")?, "fault")? != 0;
    let handshake = int::<u8>(setting(&mut f, "handshake")?, "handshake")? != 0;
    let arm = match f.next() {
        None => None,
        Some(a) => {
            let hex = a.strip_prefix("arm=").ok_or_else(|| {
                anyhow!("the settings line has {:?} after handshake=", excerpt(a))
            })?;
            Some(
                u64::from_str_radix(hex, 16)
                    .map_err(|_| anyhow!("arm = {:?} is not a fingerprint in hex", excerpt(hex)))?,
            )
        }
    };
    if f.next().is_some() {
        bail!("the settings line has fields after arm=");
    }
    if !(settings.rate_hz.is_finite() && settings.rate_hz > 0.0 && settings.t_start.is_finite()) {
        bail!("the settings line has a rate or start time that no daemon runs with");
    }
    let k = match lines.next()?.and_then(|l| l.strip_prefix("config ")) {
        Some(k) => int::<usize>(k, "config line count")?,
        None => bail!("line 3 is not the config line"),
    };
    let system = parse_system(&lines.block(k)?, None)?;
    if system.n() != n {
        bail!(
            "the settings say n = {n} but the config has {} joints",
            system.n()
        );
    }
    check_arm(&system, arm)?;
    Ok(Header {
        n,
        settings,
        start_in_fault,
        handshake,
        system,
        layout: Layout { whole, width },
    })
}

/// A robot's chain as loaded now must be the one recorded (`arm`, its fingerprint then).
fn check_arm(system: &System, arm: Option<u64>) -> Result<()> {
    match (system.identity(), arm) {
        (None, None) => Ok(()),
        (Some(id), Some(fp)) if id.fingerprint == fp => Ok(()),
        (Some(id), Some(fp)) => bail!(
            "the robot {} loads with fingerprint {:016x}, but the recording was made with {fp:016x}: \
             its description changed since (a replay needs the robot's numbers as they were)",
            id.name,
            id.fingerprint
        ),
        (Some(id), None) => bail!("the config names robot {} but the settings line has no arm=", id.name),
        (None, Some(_)) => bail!("the settings line has arm= but the config is the planar arm's"),
    }
}

/// Replays the recording at `path`: every recorded tick through a fresh [`Controller`], every
/// command compared bit for bit. An unreadable or damaged recording is an error naming the line.
pub fn replay(path: &Path) -> Result<ReplayReport> {
    let bytes = std::fs::read(path).map_err(|e| anyhow!("cannot open {}: {e}", path.display()))?;
    let text = if crate::mcap_read::is_mcap(&bytes) {
        let file =
            crate::mcap_read::parse(&bytes).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        if file.messages(crate::view::Topic::Replay).is_empty() {
            bail!(
                "{}: an MCAP recording without a /chaosd/replay channel (`chaosctl record` \
                 records from the middle of a run; `chaosd run --record NAME` makes a \
                 recording that replays)",
                path.display()
            );
        }
        file.replay_text()
            .map_err(|e| anyhow!("{}: {e}", path.display()))?
    } else {
        bytes
    };
    replay_from(std::io::Cursor::new(text)).map_err(|e| anyhow!("{}: {e}", path.display()))
}

/// [`replay`] from any reader.
pub fn replay_from(r: impl BufRead) -> Result<ReplayReport> {
    let mut lines = Lines {
        r,
        no: 0,
        buf: String::new(),
    };
    let h = header(&mut lines)?;
    control::with_dof!(h.n, N => replay_n::<N, _>(h, &mut lines))
}

fn replay_n<const N: usize, R: BufRead>(h: Header, lines: &mut Lines<R>) -> Result<ReplayReport> {
    let generator = h
        .system
        .generator::<N>(1.0 / h.settings.rate_hz)
        .map_err(|e| anyhow!("the recorded config's command interface: {e}"))?;
    let mut ctl = Controller::<N>::new(
        h.system.tick_law::<N>(),
        h.system.feedback().max_tau,
        h.settings,
    )
    .with_generator(generator);
    let chain = h.system.chain().cloned();
    if h.start_in_fault {
        ctl.enter_fault(crate::guard::FaultReason::Restored);
    }
    if h.handshake {
        ctl.require_handshake();
    }
    let mut rep = ReplayReport::default();
    loop {
        let Some(line) = lines.next()? else {
            return Ok(rep);
        };
        let line = line.to_string();
        let no = lines.no;
        let at = |e: anyhow::Error| anyhow!("line {no}: {e}");
        let mut parts = line.split(' ');
        let kind = parts.next().unwrap_or("");
        let tick: u64 = match parts.next() {
            Some(t) => int(t, "tick").map_err(at)?,
            None => bail!("line {no}: no tick number"),
        };
        if tick != rep.ticks {
            bail!("line {no}: tick {tick} where tick {} was due", rep.ticks);
        }
        match kind {
            "T" => {
                let (Some(now), Some(state), Some(cmd), None) =
                    (parts.next(), parts.next(), parts.next(), parts.next())
                else {
                    bail!("line {no}: a tick needs 4 fields after T");
                };
                let now: u64 = int(now, "now_ns").map_err(at)?;
                let state = parse_state(state, h.layout.width).map_err(at)?;
                let recorded = parse_command(cmd, h.layout).map_err(at)?;
                let o = ctl.tick(state.as_ref(), now);
                match compare(tick, recorded.as_ref(), o.command.as_ref(), h.layout.whole) {
                    None => rep.matched += 1,
                    Some(m) if rep.first_mismatch.is_none() => rep.first_mismatch = Some(m),
                    Some(_) => {}
                }
                rep.commands += u64::from(recorded.is_some());
                rep.ticks += 1;
            }
            "P" => {
                let k = int::<usize>(parts.next().unwrap_or(""), "config line count").map_err(at)?;
                let system = parse_system(&lines.block(k)?, chain.as_ref()).map_err(at)?;
                if system.n() != N || system.chain().is_some() != chain.is_some() {
                    bail!(
                        "line {no}: a parameter change for another arm ({})",
                        system.describe_arm()
                    );
                }
                ctl.set_params(system.param_block());
                rep.param_changes += 1;
            }
            "R" => {
                ctl.resume();
                rep.resumes += 1;
            }
            "S" => {
                let rest: Vec<&str> = parts.collect();
                let width = chain.is_some().then_some(h.layout.width);
                let steer = crate::replay_steer::parse(&rest, width).map_err(at)?;
                ctl.set_steer(steer);
            }
            "B" => match (parts.next(), parts.next()) {
                (Some("0"), None) => ctl.set_blocked_hold(false),
                (Some("1"), None) => ctl.set_blocked_hold(true),
                _ => bail!("line {no}: a blocked hold is 0 or 1"),
            },
            "H" => {
                let (Some(id), Some(agreed), None) = (parts.next(), parts.next(), parts.next())
                else {
                    bail!("line {no}: a handshake verdict needs a plant id and 0 or 1");
                };
                let id: u64 = int(id, "plant id").map_err(at)?;
                let agreed = match agreed {
                    "0" => false,
                    "1" => true,
                    _ => bail!("line {no}: a handshake verdict is 0 or 1"),
                };
                ctl.set_plant_verdict(id, agreed);
            }
            "G" => bail!(
                "line {no}: the daemon lost tick records at tick {tick} (its telemetry queue was full), so the recording ends there; {} of {} ticks before it replayed bit-identically",
                rep.matched,
                rep.ticks
            ),
            other => bail!("line {no}: unknown record {:?}", excerpt(other)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{tick_record, TickTimes};
    use control::Config;

    fn settings() -> ControllerSettings {
        ControllerSettings {
            rate_hz: 1000.0,
            first_order_hold: true,
            hold_after: 5,
            stale_ns: 5_000_000,
            future_slack_ns: 1_000_000,
            daemon_id: 42,
            t_start: 0.25,
        }
    }

    /// Records the tick just run at `now` as the reporter does.
    fn log_tick<const N: usize>(
        log: &mut ReplayLog,
        ctl: &Controller<N>,
        o: &crate::controller::TickOutcome<N>,
        state: Option<StateSample>,
        now: u64,
    ) {
        let times = TickTimes {
            due: now,
            woke: now,
            done: now + 1,
        };
        let ctx = crate::view::TickContext {
            chaos: control::monitor::Verdict::Unknown,
            blocked: None,
        };
        log.tick(&tick_record(ctl, o, state, times), ctx);
    }

    /// Runs a controller on synthetic states with a parameter change and a gap, recording it.
    fn record(dir: &Path) -> PathBuf {
        record_capped(dir, u64::MAX).unwrap()
    }

    /// [`record`] into a file capped at `max_bytes`: what `finish` says.
    fn record_capped(dir: &Path, max_bytes: u64) -> Result<PathBuf, String> {
        record_as(dir, "a.replay", max_bytes)
    }

    /// [`record_capped`] into `name` (MCAP unless it ends in `.replay`).
    fn record_as(dir: &Path, name: &str, max_bytes: u64) -> Result<PathBuf, String> {
        let mut cfg = Config::preset("paper").unwrap();
        cfg.feedback.t_on = 0.3;
        let system = System::Planar(cfg.clone());
        let mut log = ReplayLog::create(dir, name, &system, &settings(), false, true)
            .unwrap()
            .with_max_bytes(max_bytes);
        let mut ctl =
            Controller::<3>::new(cfg.tick_law::<3>(), cfg.feedback.capacity(), settings());
        // As the daemon runs: no plant is controlled until the handshake agrees to it (tick 20),
        // and a refusal of the same plant later (tick 300) stops control again.
        ctl.require_handshake();
        let t0 = 7_000_000_000u64;
        for k in 0..400u64 {
            if k == 20 || k == 300 {
                ctl.set_plant_verdict(5, k == 20);
            }
            if k == 150 {
                cfg.feedback.mu = 0.7;
                log.committed(&System::Planar(cfg.clone()));
                ctl.set_params(control::tick_law::ParamBlock::Planar(cfg.law_params()));
            }
            let now = t0 + k * 1_000_000 + (k * 7919) % 300_000;
            let mut s = StateSample {
                seq: k,
                stamp_ns: now - 40_000,
                plant_id: 5,
                n: 3,
                ..StateSample::default()
            };
            s.q[..3].copy_from_slice(&[0.1 * (k as f64 * 1e-2).sin(), 1.5, 1.6]);
            s.qd[..3].copy_from_slice(&[1.0 / 3.0, -0.2, (k as f64).sqrt()]);
            let newest = (k % 50 < 45).then_some(s);
            let o = ctl.tick(newest.as_ref(), now);
            log_tick(&mut log, &ctl, &o, newest, now);
        }
        log.finish()
    }

    /// A Panda's run in `mode` on synthetic states, with a live change of μ (tick 150) and a
    /// steering handover (tick 250), recorded as the daemon records it.
    fn record_panda(dir: &Path, mode: control::command::CommandMode) -> PathBuf {
        let mut system = rt::robot::preset("panda").unwrap();
        let System::Spatial(s) = &mut system else {
            unreachable!()
        };
        s.own_mut().command.mode = mode;
        let q0 = s.config.sim.start().to_vec();
        let mut log = ReplayLog::create(
            dir,
            &format!("{mode:?}.replay"),
            &system,
            &settings(),
            false,
            true,
        )
        .unwrap();
        let generator = system.generator::<7>(1e-3).unwrap();
        let mut ctl =
            Controller::<7>::new(system.tick_law::<7>(), 2.0, settings()).with_generator(generator);
        ctl.require_handshake();
        ctl.set_plant_verdict(5, true);
        let t0 = 7_000_000_000u64;
        for k in 0..400u64 {
            if k == 150 {
                let System::Spatial(s) = &mut system else {
                    unreachable!()
                };
                s.config.feedback.mu = 0.7;
                log.committed(&system);
                ctl.set_params(system.param_block());
            }
            if k == 250 {
                let cycle = control::steer::Cycle::through(
                    0.0,
                    2.0,
                    (0..8)
                        .map(|j| q0.iter().map(|q| q + 0.01 * j as f64).collect())
                        .collect(),
                );
                let steer = control::steer::SpatialSteer::of(&cycle, 1.0).unwrap();
                let steering = control::steer::Steering::Spatial(steer);
                log.steered(Some(&steering));
                ctl.set_steer(Some(steering));
            }
            let now = t0 + k * 1_000_000 + (k * 7919) % 300_000;
            let mut st = StateSample {
                seq: k,
                stamp_ns: now - 40_000,
                plant_id: 5,
                n: 7,
                ..StateSample::default()
            };
            for (i, q) in q0.iter().enumerate() {
                st.q[i] = q + 0.01 * (k as f64 * 1e-2 + i as f64).sin();
                st.qd[i] = 0.01 * (i as f64 - 3.0);
            }
            let o = ctl.tick(Some(&st), now);
            log_tick(&mut log, &ctl, &o, Some(st), now);
        }
        log.finish().unwrap()
    }

    #[test]
    fn a_panda_replays_bit_for_bit_in_every_command_mode() {
        let d = dir("panda");
        use control::command::CommandMode as M;
        for mode in [M::Acceleration, M::Position, M::Velocity, M::Torque] {
            let p = record_panda(&d, mode);
            let r = replay(&p).unwrap();
            assert!(r.all_matched(), "{mode:?}: {r}");
            assert_eq!((r.ticks, r.param_changes), (400, 1), "{mode:?}");
            assert!(r.commands > 350, "{mode:?}: {r}");
            let text = std::fs::read_to_string(&p).unwrap();
            assert!(
                text.contains("\nS 250 1 ") && text.contains(" arm="),
                "{mode:?}"
            );
            // A torque or a reference changed by one bit late in the run: found.
            let mut lines: Vec<String> = text.lines().map(String::from).collect();
            let i = lines.iter().position(|l| l.starts_with("T 300 ")).unwrap();
            let mut fields: Vec<String> = lines[i].split(',').map(String::from).collect();
            let q0 = fields.len() - 3 * MAX_JOINTS; // the command's q[0]
            let v = u64::from_str_radix(&fields[q0], 16).unwrap() ^ 1;
            fields[q0] = format!("{v:016x}");
            lines[i] = fields.join(",");
            std::fs::write(&p, lines.join("\n") + "\n").unwrap();
            let m = replay(&p).unwrap().first_mismatch.unwrap();
            assert_eq!(
                (m.tick, m.field.as_str()),
                (300, "command.q[0]"),
                "{mode:?}"
            );
            // A recording of another robot's numbers is refused by name.
            let at = text.find(" arm=").unwrap() + 5;
            let fp = u64::from_str_radix(&text[at..at + 16], 16).unwrap();
            let other = text.replacen(&text[at..at + 16], &format!("{:016x}", fp ^ 1), 1);
            std::fs::write(&p, other).unwrap();
            let e = replay(&p).unwrap_err().to_string();
            assert!(e.contains("description changed since"), "{e}");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("chaosd-replay-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        rt::files::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_run_replays_bit_for_bit_and_a_changed_bit_is_found() {
        let d = dir("ok");
        let p = record(&d);
        let r = replay(&p).unwrap();
        assert!(r.all_matched(), "{r}");
        assert_eq!((r.ticks, r.param_changes), (400, 1));
        assert!(r.commands > 300);
        // Flip the lowest bit of one recorded q̈ (tick 200): found, with the exact bits.
        let text = std::fs::read_to_string(&p).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let i = lines.iter().position(|l| l.starts_with("T 200 ")).unwrap();
        let mut fields: Vec<String> = lines[i].split(',').map(String::from).collect();
        let qdd1 = fields.len() - 5 * MAX_JOINTS + 1; // the command's qdd[1]
        let v = u64::from_str_radix(&fields[qdd1], 16).unwrap() ^ 1;
        fields[qdd1] = format!("{v:016x}");
        lines[i] = fields.join(",");
        std::fs::write(&p, lines.join("\n") + "\n").unwrap();
        let r = replay(&p).unwrap();
        assert!(!r.all_matched());
        assert_eq!(r.matched, 399);
        let m = r.first_mismatch.unwrap();
        assert_eq!((m.tick, m.field.as_str()), (200, "command.qdd[1]"));
        assert!(m.recorded.contains(&format!("0x{v:016x}")), "{m}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// The first `OLD_WIDTH` entries of each of `arrays` per-joint arrays after `head` fields
    /// (the entries dropped are zero: the arm has at most 7 joints).
    fn narrow(text: &str, head: usize, arrays: usize) -> String {
        if text == "-" {
            return text.into();
        }
        let f: Vec<&str> = text.split(',').collect();
        assert_eq!(f.len(), head + arrays * MAX_JOINTS, "{text}");
        let mut out: Vec<&str> = f[..head].to_vec();
        for a in f[head..].chunks(MAX_JOINTS) {
            assert!(a[OLD_WIDTH..].iter().all(|v| *v == "0000000000000000"));
            out.extend(&a[..OLD_WIDTH]);
        }
        out.join(",")
    }

    /// `text` (format 4) as format 3 wrote it: every array, and a robot's steering postures,
    /// 7 entries long.
    fn as_format_3(text: &str) -> String {
        let spatial = text.contains(" arm=");
        let mut out = String::new();
        for line in text.lines() {
            let line = line.replacen("chaosd-replay 4", "chaosd-replay 3", 1);
            let mut parts: Vec<String> = line.split(' ').map(String::from).collect();
            if parts[0] == "T" {
                parts[3] = narrow(&parts[3], 6, 2);
                parts[4] = narrow(&parts[4], 8, 5);
            }
            if parts[0] == "S" && parts[2] == "1" && spatial {
                let postures = parts[8..].join(",");
                let head = parts[..8].join(" ");
                let k: usize = parts[7].parse().unwrap();
                let narrowed = narrow(&format!("x,{postures}"), 1, k);
                parts = vec![head, narrowed[2..].replace(',', " ")];
            }
            out.push_str(&parts.join(" "));
            out.push('\n');
        }
        out
    }

    /// `text` (format 4) as format 2 wrote it: arrays of 7, the command without interface, q,
    /// qd and tau.
    fn as_format_2(text: &str) -> String {
        let mut out = String::new();
        for line in as_format_3(text).lines() {
            let line = line.replacen("chaosd-replay 3", "chaosd-replay 2", 1);
            let mut parts: Vec<String> = line.split(' ').map(String::from).collect();
            if parts[0] == "T" && parts[4] != "-" {
                let f: Vec<&str> = parts[4].split(',').collect();
                let mut short: Vec<&str> = f[..7].to_vec();
                short.extend(&f[8..8 + 2 * OLD_WIDTH]);
                parts[4] = short.join(",");
            }
            out.push_str(&parts.join(" "));
            out.push('\n');
        }
        out
    }

    /// Recordings made when the capacity was 7 (format 3) replay bit for bit: the planar arm,
    /// and the Panda in a command mode with steering.
    #[test]
    fn a_format_3_recording_still_replays_bit_for_bit() {
        let d = dir("v3");
        for p in [
            record(&d),
            record_panda(&d, control::command::CommandMode::Position),
        ] {
            let v3 = as_format_3(&std::fs::read_to_string(&p).unwrap());
            assert!(v3.starts_with("chaosd-replay 3\n"));
            std::fs::write(&p, &v3).unwrap();
            let r = replay(&p).unwrap();
            assert!(r.all_matched(), "{r}");
            assert_eq!((r.ticks, r.param_changes), (400, 1));
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_format_2_recording_still_replays_on_what_it_holds() {
        let d = dir("v2");
        let p = record(&d);
        let v2 = as_format_2(&std::fs::read_to_string(&p).unwrap());
        std::fs::write(&p, &v2).unwrap();
        let r = replay(&p).unwrap();
        assert!(r.all_matched(), "{r}");
        assert_eq!((r.ticks, r.param_changes), (400, 1));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_reference_or_torque_that_differs_is_found_in_format_4() {
        let d = dir("whole");
        let p = record(&d);
        let text = std::fs::read_to_string(&p).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let i = lines.iter().position(|l| l.starts_with("T 200 ")).unwrap();
        let mut fields: Vec<String> = lines[i].split(',').map(String::from).collect();
        let tau6 = fields.len() - 1; // the command's tau[MAX_JOINTS - 1]
        fields[tau6] = format!("{:016x}", 1.5f64.to_bits());
        lines[i] = fields.join(",");
        std::fs::write(&p, lines.join("\n") + "\n").unwrap();
        let m = replay(&p).unwrap().first_mismatch.unwrap();
        assert_eq!((m.tick, m.field.as_str()), (200, "command.tau[11]"));
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn an_mcap_recording_replays_bit_for_bit_and_holds_the_same_text_and_the_view_channels() {
        let d = dir("mcap");
        let p = record_as(&d, "a.mcap", u64::MAX).unwrap();
        let r = replay(&p).unwrap();
        assert!(r.all_matched(), "{r}");
        assert_eq!((r.ticks, r.param_changes), (400, 1));
        let text_path = record(&d);
        let file = crate::mcap_read::read(&p).unwrap();
        let lines = file.replay_text().unwrap();
        // The settings line names the daemon and its clock, so it is the same in both files.
        assert_eq!(lines, std::fs::read(&text_path).unwrap());
        assert_eq!(file.messages(crate::view::Topic::Replay).len(), 400);
        let states = file.messages(crate::view::Topic::JointStates).len();
        assert!(states > 200 && states < 400, "{states}"); // the ticks whose law ran
                                                           // A recording made with `chaosctl record` has no replay channel: said in words.
        let sys = control::System::Planar(Config::preset("paper").unwrap());
        let limit = crate::rotate::Limit {
            max_bytes: None,
            keep: 0,
        };
        let rec = crate::mcap_recording::McapRecording::start(&d, "b.mcap", &sys, 1e3, limit);
        rec.unwrap().finish().unwrap();
        let e = replay(&d.join("b.mcap")).unwrap_err().to_string();
        assert!(e.contains("without a /chaosd/replay channel"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_capped_recording_stops_at_its_cap_and_replays_up_to_there() {
        let d = dir("cap");
        let full_path = record(&d);
        let full = std::fs::metadata(&full_path).unwrap().len();
        std::fs::remove_file(full_path).unwrap();
        let cap = full / 2;
        let why = record_capped(&d, cap).unwrap_err();
        assert!(
            why.contains("record_max_bytes") && why.contains("stops rather than rotates"),
            "{why}"
        );
        let p = d.join("a.replay");
        let size = std::fs::metadata(&p).unwrap().len();
        // Stopped within two tick lines of the cap (one is about 1.5 kB with arrays of 12).
        assert!(
            size <= cap && size > cap - 4000,
            "{size} bytes for a cap of {cap}"
        );
        let r = replay(&p).unwrap();
        assert!(r.all_matched(), "{r}");
        assert!(r.ticks > 100 && r.ticks < 400, "{} ticks", r.ticks);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn damaged_recordings_are_refused_by_line_never_a_panic() {
        let d = dir("bad");
        let p = record(&d);
        let text = std::fs::read_to_string(&p).unwrap();
        let cut = |n: usize| text[..n].to_string();
        let t_line = text.find("\nT 10 ").unwrap() + 1;
        for (bad, want) in [
            (String::new(), "not a chaosd replay"),
            (
                "t,state_seq\n1,2\n".to_string(),
                "CSV files cannot be replayed",
            ),
            (cut(t_line + 20), "truncated"),
            (text.replacen("T 10 ", "T 11 ", 1), "tick 11 where tick 10"),
            (text.replacen("T 10 ", "X 10 ", 1), "unknown record"),
            (
                text.replacen("settings n=3", "settings n=x", 1),
                "n = \"x\"",
            ),
            (text.replacen("config ", "config 9", 1), "config"),
            (
                text.replacen("handshake=1", "handshake=1 arm=00000000000000ff", 1),
                "the config is the planar arm's",
            ),
            (
                text.replacen("handshake=1", "handshake=1 robot=panda", 1),
                "after handshake=",
            ),
            (
                text.replace(",3fd5555555555555,", ",3fd55555555zz555,"),
                "not hex",
            ),
            (
                text.replacen("T 10 ", "G 10 3\nT 10 ", 1),
                "lost tick records",
            ),
            (format!("{}\n", "x".repeat(100_000)), "longer than"),
            (
                text.replacen("chaosd-replay 4", "chaosd-replay 1", 1),
                "format 1 (6-joint arrays",
            ),
        ] {
            std::fs::write(&p, &bad).unwrap();
            let e = replay(&p).unwrap_err().to_string();
            assert!(e.contains(want), "{want}: {e}");
            assert!(e.len() < 1024 && !e.contains('\n'), "{e}");
        }
        assert!(replay(&d.join("missing"))
            .unwrap_err()
            .to_string()
            .contains("cannot open"));
        std::fs::remove_dir_all(&d).unwrap();
    }
}
