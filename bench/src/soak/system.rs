//! The system under test as the soak sees it: the daemon and plant processes, what they say
//! about themselves (control-service status, the plant's state flags), and /proc.
//!
//! The soak asks the system, never guesses: every detection and recovery is read from a status
//! answer or from the flags the plant publishes with its states.

use crate::child::{Child, Stdout};
use anyhow::{anyhow, bail, Context, Result};
use iceoryx2::port::client::Client;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use protocol::control::{ControlService, MAX_BODY};
use protocol::{ControlRequest, ControlResponse, Op, ServiceNames, StateSample};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// How long a status request may take before it counts as unanswered. Generous: the machine is
/// shared and a loaded reporter thread is not a fault.
pub const ANSWER_LIMIT: Duration = Duration::from_secs(2);

/// The config both processes read: the service defaults, with sleeping waits (the soak shares
/// its cores with everyone else) and SCHED_FIFO 40 where permitted.
pub fn config_text(namespace: &str, dir: &Path) -> String {
    format!(
        "[daemon]\nnamespace = \"{namespace}\"\noutput_dir = '{dir}'\nwait = \"sleep\"\npriority = {DAEMON_PRIORITY}\nreport_every_s = 0.0\n\n\
         [plant]\nnamespace = \"{namespace}\"\noutput_dir = '{dir}'\nwait = \"sleep\"\npriority = {DAEMON_PRIORITY}\n",
        dir = dir.display()
    )
}

/// The daemon's SCHED_FIFO priority in the soak; the hog runs one above it.
pub const DAEMON_PRIORITY: u8 = 40;

/// `chaosd` or `chaosd-plant`, next to this executable.
pub fn sibling(name: &str) -> Result<PathBuf> {
    let me = std::env::current_exe().context("cannot locate the chaosd-bench executable")?;
    let p = me.with_file_name(name);
    if !p.is_file() {
        bail!(
            "{} not found next to chaosd-bench: build it first, e.g. `cargo build --release -p daemon -p plant`",
            p.display()
        );
    }
    Ok(p)
}

/// Resident set size (kB) and open file descriptors of a process, from /proc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProcSample {
    pub at: Instant,
    pub rss_kb: u64,
    pub fds: usize,
}

pub fn proc_sample(pid: u32) -> Option<ProcSample> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let rss_kb = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).ok()?.count();
    Some(ProcSample {
        at: Instant::now(),
        rss_kb,
        fds,
    })
}

/// One process's life: from a start to a kill -9 or a clean stop.
pub struct Lifetime {
    pub pid: u32,
    pub samples: Vec<ProcSample>,
    /// How it ended: "kill -9", "SIGTERM (exit 0)", ...
    pub end: Option<String>,
}

/// A daemon or plant process and the record of its lifetimes.
pub struct Role {
    pub name: &'static str,
    exe: PathBuf,
    args: Vec<String>,
    dir: PathBuf,
    pub child: Option<Child>,
    pub lives: Vec<Lifetime>,
}

impl Role {
    pub fn new(name: &'static str, exe: PathBuf, args: Vec<String>, dir: &Path) -> Self {
        Self {
            name,
            exe,
            args,
            dir: dir.to_path_buf(),
            child: None,
            lives: Vec::new(),
        }
    }

    /// Starts the process (a new lifetime, its own log file).
    pub fn start(&mut self, extra: &[&str]) -> Result<u32> {
        let mut cmd = Command::new(&self.exe);
        cmd.args(&self.args).args(extra);
        let log = self
            .dir
            .join(format!("{}-{}.log", self.name, self.lives.len() + 1));
        let child = Child::spawn(self.name, cmd, &log, Stdout::Log)?;
        let pid = child
            .pid()
            .ok_or_else(|| anyhow!("{} has no pid", self.name))?;
        self.child = Some(child);
        self.lives.push(Lifetime {
            pid,
            samples: Vec::new(),
            end: None,
        });
        Ok(pid)
    }

    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().and_then(|c| c.pid())
    }

    pub fn signal(&self, sig: i32) -> Result<()> {
        let pid = self
            .pid()
            .ok_or_else(|| anyhow!("{} is not running", self.name))?;
        // SAFETY: kill(2) on our own, not yet reaped, child.
        if unsafe { libc::kill(pid as i32, sig) } != 0 {
            bail!("cannot signal {} (pid {pid})", self.name);
        }
        Ok(())
    }

    /// kill -9 and reap.
    pub fn kill9(&mut self) {
        if let Some(mut c) = self.child.take() {
            c.kill();
        }
        self.end("kill -9".into());
    }

    /// SIGTERM and a clean exit within `grace` (the daemon's hard stop is 10 s).
    pub fn stop(&mut self, grace: Duration) -> Result<()> {
        let Some(mut c) = self.child.take() else {
            bail!("{} is not running", self.name);
        };
        let r = c.terminate(grace);
        let ok = matches!(&r, Ok(st) if st.success());
        let how = match &r {
            Ok(st) => format!("SIGTERM ({st})"),
            Err(_) => "SIGTERM ignored, killed".into(),
        };
        self.end(how.clone());
        if !ok {
            return Err(c.failure(&format!("it did not stop cleanly: {how}")));
        }
        Ok(())
    }

    fn end(&mut self, how: String) {
        if let Some(l) = self.lives.last_mut() {
            if l.end.is_none() {
                l.end = Some(how);
            }
        }
    }

    /// Fails if the process exited on its own.
    pub fn check_alive(&mut self) -> Result<()> {
        if let Some(c) = self.child.as_mut() {
            if c.poll_exit().is_some() {
                let e = c.failure("it exited by itself during the soak");
                self.child = None;
                self.end("exited by itself".into());
                return Err(e);
            }
        }
        Ok(())
    }

    pub fn sample(&mut self) {
        if let Some(pid) = self.pid() {
            if let (Some(s), Some(l)) = (proc_sample(pid), self.lives.last_mut()) {
                l.samples.push(s);
            }
        }
    }
}

/// A status answer, reduced to what the soak judges by.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Status {
    pub pid: u64,
    /// "Run", "Hold", "Fault", "Brake", or "" before the first tick.
    pub mode: String,
    pub mu: Option<f64>,
    pub ticks: u64,
    pub fresh: u64,
    pub rejected_invalid: u64,
    pub rejected_future: u64,
    pub rejected_out_of_order: u64,
    pub rejected_stale: u64,
    pub holds: u64,
    pub plant_restarts: u64,
    pub overruns: u64,
    pub telemetry_dropped: u64,
    pub faults: u64,
    pub params_applied: u64,
    pub recording_error: Option<String>,
}

impl Status {
    pub fn parse(body: &str) -> Result<Self> {
        let v: Value = serde_json::from_str(body).context("status is not JSON")?;
        let c = &v["counters"];
        let n = |k: &str| c[k].as_u64().unwrap_or(0);
        Ok(Self {
            pid: v["pid"].as_u64().unwrap_or(0),
            mode: v["mode"].as_str().unwrap_or("").to_string(),
            mu: v["mu"].as_f64(),
            ticks: n("ticks"),
            fresh: n("fresh_states"),
            rejected_invalid: n("rejected_invalid"),
            rejected_future: n("rejected_future"),
            rejected_out_of_order: n("rejected_out_of_order"),
            rejected_stale: n("rejected_stale"),
            holds: n("holds_entered"),
            plant_restarts: n("plant_restarts"),
            overruns: n("overruns"),
            telemetry_dropped: n("telemetry_dropped"),
            faults: n("faults"),
            params_applied: n("params_applied"),
            recording_error: v["recording_error"].as_str().map(str::to_string),
        })
    }
}

/// An answer: Ok(body) or Refused(body).
pub type Answer = std::result::Result<String, String>;

/// Clients of the daemon's control service. Several, because iceoryx2 allows one request in
/// flight per client and the soak sometimes needs a few handled together.
pub struct Control {
    names: ServiceNames,
    service: Option<ControlService<ipc::Service>>,
    clients: Vec<Client<ipc::Service, ControlRequest, (), ControlResponse, ()>>,
    next_id: u64,
}

/// Clients the soak opens (the service allows 16).
const CLIENTS: usize = 6;

impl Control {
    pub fn new(names: &ServiceNames) -> Self {
        Self {
            names: names.clone(),
            service: None,
            clients: Vec::new(),
            next_id: 1,
        }
    }

    /// Drops the clients (after the daemon was killed: they are opened again on next use).
    pub fn reset(&mut self) {
        self.clients.clear();
        self.service = None;
    }

    fn connect(&mut self, node: &iceoryx2::node::Node<ipc::Service>) -> Result<()> {
        if self.clients.len() == CLIENTS {
            return Ok(());
        }
        self.reset();
        let svc = protocol::control::open_control_service(node, &self.names)?;
        for _ in 0..CLIENTS {
            self.clients.push(
                svc.client_builder()
                    .create()
                    .map_err(|e| anyhow!("cannot create a control client: {e:?}"))?,
            );
        }
        self.service = Some(svc);
        Ok(())
    }

    /// Sends `reqs` at once (one per client, in order) and waits up to `limit` for every
    /// answer. `None` for a request that got no answer (the daemon is down or stopped).
    pub fn batch(
        &mut self,
        node: &iceoryx2::node::Node<ipc::Service>,
        reqs: &[(Op, &str)],
        limit: Duration,
    ) -> Vec<Option<Answer>> {
        assert!(reqs.len() <= CLIENTS, "at most {CLIENTS} requests at once");
        let mut out = vec![None; reqs.len()];
        if self.connect(node).is_err() {
            return out;
        }
        let mut pending = Vec::new();
        for (i, (op, args)) in reqs.iter().enumerate() {
            self.next_id += 1;
            let Ok(req) = ControlRequest::new(self.next_id, *op, args) else {
                out[i] = Some(Err("arguments too long".into()));
                continue;
            };
            match self.clients[i].send_copy(req) {
                Ok(p) if p.number_of_server_connections() > 0 => pending.push((i, p)),
                _ => {}
            }
        }
        let until = Instant::now() + limit;
        while !pending.is_empty() && Instant::now() < until {
            pending.retain(|(i, p)| match p.receive() {
                Ok(Some(r)) => {
                    let r: ControlResponse = *r;
                    let body = r.body().unwrap_or("malformed answer").to_string();
                    debug_assert!(body.len() <= MAX_BODY);
                    out[*i] = Some(if r.is_ok() { Ok(body) } else { Err(body) });
                    false
                }
                Ok(None) => true,
                Err(_) => false,
            });
            if !pending.is_empty() {
                std::thread::sleep(Duration::from_micros(200));
            }
        }
        if out.iter().any(Option::is_none) {
            // A lost answer leaves a request in flight on that client: start over next time.
            self.reset();
        }
        out
    }

    pub fn one(
        &mut self,
        node: &iceoryx2::node::Node<ipc::Service>,
        op: Op,
        args: &str,
    ) -> Option<Answer> {
        self.batch(node, &[(op, args)], ANSWER_LIMIT)
            .pop()
            .flatten()
    }
}

/// The plant's states as published: who the plant is and what it says about itself.
pub struct StateWatch {
    sub: Subscriber<ipc::Service, StateSample, ()>,
    pub last: Option<StateSample>,
    pub last_at: Option<Instant>,
}

impl StateWatch {
    pub fn new(node: &iceoryx2::node::Node<ipc::Service>, names: &ServiceNames) -> Result<Self> {
        let svc = protocol::open_state_service(node, names)?;
        let sub = svc
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow!("cannot subscribe to {}: {e:?}", names.state()))?;
        Ok(Self {
            sub,
            last: None,
            last_at: None,
        })
    }

    /// Drains the queue; returns the flags of every state seen (OR-ed).
    pub fn poll(&mut self) -> u32 {
        let mut seen = 0;
        while let Ok(Some(s)) = self.sub.receive() {
            seen |= s.flags;
            self.last = Some(*s);
            self.last_at = Some(Instant::now());
        }
        seen
    }
}
