//! `latency`: what one state → command exchange costs on each transport chaosd could use.
//!
//! Two processes, pinned to two cores, play ping-pong: this one sends a [`protocol::StateSample`]
//! and waits for the [`protocol::CommandSample`] that answers it; a copy of this binary (the
//! hidden `__latency-peer` subcommand) answers. The round trip is timed on this side only, with
//! one CLOCK_MONOTONIC read before the send and one after the reply, so no clocks are compared
//! across cores.
//!
//! The transports run interleaved in short blocks ([`crate::plan`]), so a slow minute on the
//! host hits all of them alike and their ratios stay meaningful. The floor is a sequence number
//! and a payload in shared memory that both sides spin on: two cache-line transfers per round
//! trip, which no transport between two cores can beat. Each series is reported with its ratio
//! to that floor.
//!
//! The crossbeam series runs between two threads of this process (pinned the same way), since a
//! channel cannot cross processes; it shows what the kernel-free in-process alternative costs.

pub mod link;

use crate::book::names;
use crate::child::{Child, Stdout};
use crate::plan::interleave;
use crate::plot::Panel;
use crate::report::{header, Output, Report};
use crate::stats::{fmt_ns, fmt_ratio, histogram, ratio, summary, Bound, Dist, Table, Target};
use anyhow::{anyhow, bail, Context, Result};
use hdrhistogram::Histogram;
use link::{BoardLink, ChanLink, IoxListen, IoxPoll, IoxPorts, Pace, ShmRegion, UdpLink, UnixLink};
use protocol::ServiceNames;
use std::io::{BufRead, Write};
use std::net::UdpSocket;
use std::os::fd::FromRawFd;
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// The transports, in table order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    Shm,
    IoxPoll,
    IoxBoard,
    IoxListener,
    IoxWaitSet,
    Unix,
    Udp,
    Crossbeam,
}

impl Kind {
    pub const ALL: [Kind; 8] = [
        Kind::Shm,
        Kind::IoxPoll,
        Kind::IoxBoard,
        Kind::IoxListener,
        Kind::IoxWaitSet,
        Kind::Unix,
        Kind::Udp,
        Kind::Crossbeam,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Kind::Shm => "shared-memory spin flag (floor)",
            Kind::IoxPoll => "iceoryx2 pub-sub, busy polling",
            Kind::IoxBoard => "iceoryx2 blackboard (latest value), busy polling",
            Kind::IoxListener => "iceoryx2 pub-sub + event, Listener wait",
            Kind::IoxWaitSet => "iceoryx2 pub-sub + event, WaitSet wait",
            Kind::Unix => "Unix domain socket (stream)",
            Kind::Udp => "UDP over 127.0.0.1",
            Kind::Crossbeam => "crossbeam channel, 2 threads",
        }
    }

    pub fn slug(self) -> &'static str {
        match self {
            Kind::Shm => "shm-spin",
            Kind::IoxPoll => "iox-poll",
            Kind::IoxBoard => "iox-board",
            Kind::IoxListener => "iox-listener",
            Kind::IoxWaitSet => "iox-waitset",
            Kind::Unix => "unix",
            Kind::Udp => "udp",
            Kind::Crossbeam => "crossbeam",
        }
    }

    pub fn from_slug(s: &str) -> Option<Kind> {
        Kind::ALL.into_iter().find(|k| k.slug() == s)
    }

    /// Whether the peer process takes part (the channel is between our own threads).
    fn remote(self) -> bool {
        self != Kind::Crossbeam
    }

    fn index(self) -> usize {
        Kind::ALL
            .iter()
            .position(|&k| k == self)
            .expect("every kind is in ALL")
    }
}

/// How much to measure, and where.
#[derive(Clone, Debug)]
pub struct Options {
    /// Measured rounds (one block per transport each), after one warm-up round.
    pub rounds: usize,
    /// Recorded round trips per block.
    pub round_trips: usize,
    /// Unrecorded round trips at the start of each block (the peer wakes up from its pipe read).
    pub warm: usize,
    /// SCHED_FIFO priority of both sides (0: normal scheduler); by default the daemon's.
    pub priority: u8,
    /// Cores of this side and of the peer.
    pub cores: (usize, usize),
    /// How long a side waits for one message before it gives up.
    pub timeout: Duration,
    /// Round trips spaced at a loop's period (the floor at that rate), or back to back.
    pub pace: Option<Pace>,
}

impl Options {
    pub fn new(quick: bool) -> Self {
        Self {
            rounds: if quick { 10 } else { 40 },
            round_trips: if quick { 2_000 } else { 5_000 },
            warm: 50,
            priority: daemon::config::DaemonConfig::default().priority.min(98),
            cores: (0, 1),
            timeout: Duration::from_secs(2),
            pace: None,
        }
    }
}

/// A namespace no other run shares (pid + wall-clock nanoseconds).
pub fn unique_namespace(tag: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("bench-{tag}-{}-{nanos}", std::process::id())
}

fn apply_rt(core: usize, priority: u8, who: &str) -> rt::setup::RtReport {
    let r = rt::setup::apply(rt::setup::RtRequest {
        core: Some(core),
        priority,
        lock_memory: false,
    });
    for w in &r.warnings {
        eprintln!("chaosd-bench: {who}: warning: {w}");
    }
    r
}

/// Runs the benchmark and returns its report (also written to `<out>/latency/`).
pub fn run(opts: &Options, out: &Path, command: &str) -> Result<Output> {
    let opts = opts.clone();
    let out = out.to_path_buf();
    let command = command.to_string();
    // A thread of its own: it is pinned (maybe SCHED_FIFO) and owns the !Send iceoryx2 ports,
    // and it outlives the peer it spawns (PR_SET_PDEATHSIG follows the spawning thread).
    std::thread::Builder::new()
        .name("latency".into())
        .spawn(move || measure(&opts, &out, &command))?
        .join()
        .map_err(|_| anyhow!("the latency thread panicked"))?
}

fn measure(opts: &Options, out: &Path, command: &str) -> Result<Output> {
    let mut report = Report::new(out, "latency")?;
    let (core_a, core_b) = opts.cores;
    let (timeout, pace) = (opts.timeout, opts.pace);
    let names = ServiceNames::new(&unique_namespace("lat")).map_err(|e| anyhow!("{e}"))?;

    // The echo thread first: threads inherit the spawner's affinity, and this one is pinned next.
    let (to_echo, echo_rx) = crossbeam::channel::bounded::<protocol::StateSample>(1);
    let (echo_tx, from_echo) = crossbeam::channel::bounded(1);
    let priority = opts.priority;
    let echo = std::thread::Builder::new()
        .name("latency-echo".into())
        .spawn(move || {
            apply_rt(core_b, priority, "latency echo thread");
            while let Ok(s) = echo_rx.recv() {
                if echo_tx.send(link::answer(&s)).is_err() {
                    break;
                }
            }
        })?;
    let chan = ChanLink {
        tx: to_echo,
        rx: from_echo,
    };
    let rt = apply_rt(core_a, opts.priority, "latency");

    // Everything this side needs before the peer starts: its subscriber must exist before the
    // peer's first send, and the peer inherits the memfd and its socketpair end.
    let ports = IoxPorts::parent(&names)?;
    let board = BoardLink::parent(&names)?;
    let mut shm = ShmRegion::create()?;
    let (unix_ours, unix_theirs) = link::unix_pair()?;
    let udp = UdpSocket::bind("127.0.0.1:0").context("cannot bind a UDP socket on 127.0.0.1")?;
    let exe = std::env::current_exe().context("cannot locate the chaosd-bench executable")?;
    let mut cmd = Command::new(exe);
    cmd.arg("__latency-peer")
        .args(["--namespace", names.namespace()])
        .args([
            "--shm-fd",
            &shm.fd().expect("a fresh region has its fd").to_string(),
        ])
        .args(["--unix-fd", &unix_theirs.to_string()])
        .args(["--udp-port", &udp.local_addr()?.port().to_string()])
        .args(["--core", &core_b.to_string()])
        .args(["--priority", &opts.priority.to_string()])
        .args(["--timeout-ms", &timeout.as_millis().to_string()]);
    let spawned = Child::spawn("latency peer", cmd, &report.path("peer.log"), Stdout::Lines);
    shm.close_fd();
    // SAFETY: closing our copy of the peer's end, once; the peer holds its own.
    unsafe { libc::close(unix_theirs) };
    let mut peer = spawned?;
    let ready = peer.expect("ready", Duration::from_secs(30))?;
    let port: u16 = ready
        .strip_prefix("udp=")
        .and_then(|p| p.parse().ok())
        .ok_or_else(|| peer.failure(&format!("bad ready line {ready:?}")))?;
    udp.connect(("127.0.0.1", port))
        .context("cannot connect the UDP socket")?;
    let (shm_link, unix, udp) = (
        shm.parent(),
        UnixLink::new(unix_ours, timeout)?,
        UdpLink::new(udp, timeout)?,
    );

    let mut hists: Vec<Histogram<u64>> = Kind::ALL.iter().map(|_| histogram()).collect();
    let mut scratch = histogram();
    let mut seq = 0u64;
    let started = std::time::SystemTime::now();
    let t0 = std::time::Instant::now();
    for (round, order) in interleave(&Kind::ALL, opts.rounds + 1)
        .into_iter()
        .enumerate()
    {
        for kind in order {
            if rt::signal::stop_requested() {
                bail!("interrupted");
            }
            // Round 0 warms every path up (page faults, connection set-up) and is not recorded.
            let (n, h) = if round == 0 {
                (opts.round_trips.div_ceil(4), &mut scratch)
            } else {
                (opts.round_trips, &mut hists[kind.index()])
            };
            let total = opts.warm + n;
            if kind.remote() {
                peer.send(&format!("run {} {total}", kind.slug()))?;
            }
            let result = match kind {
                Kind::Shm => link::ping_block(&shm_link, &mut seq, opts.warm, n, timeout, pace, h),
                Kind::IoxPoll => {
                    link::ping_block(&IoxPoll(&ports), &mut seq, opts.warm, n, timeout, pace, h)
                }
                Kind::IoxBoard => {
                    link::ping_block(&board, &mut seq, opts.warm, n, timeout, pace, h)
                }
                Kind::IoxListener => {
                    link::ping_block(&IoxListen(&ports), &mut seq, opts.warm, n, timeout, pace, h)
                }
                Kind::IoxWaitSet => link::with_waitset(&ports, |l| {
                    link::ping_block(l, &mut seq, opts.warm, n, timeout, pace, h)
                }),
                Kind::Unix => {
                    link::ping_block::<UnixLink>(&unix, &mut seq, opts.warm, n, timeout, pace, h)
                }
                Kind::Udp => {
                    link::ping_block::<UdpLink>(&udp, &mut seq, opts.warm, n, timeout, pace, h)
                }
                Kind::Crossbeam => {
                    link::ping_block(&chan, &mut seq, opts.warm, n, timeout, pace, h)
                }
            };
            if let Err(e) = result {
                let why = if kind.remote() {
                    format!("\n{:#}", peer.failure("the peer did not keep up"))
                } else {
                    String::new()
                };
                bail!("{} failed: {e:#}{why}", kind.label());
            }
            if kind.remote() {
                let done = peer.expect("done", Duration::from_secs(60))?;
                if done != format!("{} {total}", kind.slug()) {
                    bail!(peer.failure(&format!(
                        "it finished {done:?}, expected {} {total}",
                        kind.slug()
                    )));
                }
            }
        }
    }
    let elapsed = t0.elapsed();
    peer.send("quit")?;
    peer.wait_success(Duration::from_secs(30))?;
    drop(chan);
    echo.join()
        .map_err(|_| anyhow!("the echo thread panicked"))?;

    let scheduler = match rt.sched_fifo {
        Some(p) => format!("SCHED_FIFO {p}"),
        None => "SCHED_OTHER".into(),
    };
    report.push(&header("Round-trip latency", command));
    report.push(&format!(
        "Ping-pong of a StateSample ({} B) and the CommandSample ({} B) answering it between two processes pinned to \
         cores {core_a} and {core_b} ({scheduler}); crossbeam between two threads pinned the same way. \
         {} interleaved rounds of {} round trips per transport (after a warm-up round), {:.1} s in all.\n\n",
        std::mem::size_of::<protocol::StateSample>(),
        std::mem::size_of::<protocol::CommandSample>(),
        opts.rounds,
        opts.round_trips,
        elapsed.as_secs_f64()
    ));
    report.push(&pace_line(pace));
    let (text, targets) = table(&hists);
    report.run_detail(format!(
        "{} rounds × {} round trips per transport{}",
        opts.rounds,
        opts.round_trips,
        pace.map_or(String::new(), |p| format!(
            ", paced at {} µs",
            p.period_ns / 1000
        ))
    ));
    let name = match pace {
        None => names::LATENCY,
        Some(_) => names::LATENCY_PACED,
    };
    report.table(name, &text)?;
    report.push("\n");
    // The targets compare transports back to back; paced, the table is a floor, not a contest.
    if pace.is_none() {
        for t in &targets {
            report.push(&t.line());
        }
    }
    let floor = summary(&hists[Kind::Shm.index()])[0] as f64;
    let poll = summary(&hists[Kind::IoxPoll.index()])[0] as f64;
    report.push(&format!(
        "\niceoryx2 polling costs {} per round trip above the floor (a loan, a send and a receive in each direction); \
         the floor itself is two cache-line transfers between the cores.\n",
        fmt_ns(poll - floor)
    ));

    let mut tagged = Vec::new();
    for k in Kind::ALL {
        report.hgrm(k.slug(), &hists[k.index()])?;
        tagged.push((k.slug(), &hists[k.index()]));
    }
    let hlog = report.path("latency.hlog");
    rt::hist::save_hlog(&tagged, started, elapsed, &hlog)
        .with_context(|| format!("cannot write {}", hlog.display()))?;
    report.files.push(hlog);
    let series = Kind::ALL
        .iter()
        .map(|k| Dist::of_histogram(k.label(), &hists[k.index()]))
        .collect();
    report.plot(
        "chaosd-bench latency: state → command round trip",
        &[Panel {
            title: format!("round trip between cores {core_a} and {core_b}, {scheduler}"),
            quantity: "round trip".into(),
            series,
        }],
    )?;
    report.finish()
}

/// What the report says about pacing.
fn pace_line(pace: Option<Pace>) -> String {
    match pace {
        None => "Back to back: each ping leaves as soon as the previous answer came.\n\n".into(),
        Some(p) => format!(
            "**Paced**: one ping every {} µs, the sender waiting for it with the `{}` strategy \
             (spin window {} µs), as the plant does at that rate; the answering side waits as \
             each transport does (polling ones spin throughout). This is the floor under \
             chaosd's end-to-end state → command latency at that rate on this machine.\n\n",
            p.period_ns / 1000,
            p.wait.name(),
            p.spin_ns / 1000
        ),
    }
}

/// The results table and the two targets.
pub fn table(hists: &[Histogram<u64>]) -> (String, Vec<Target>) {
    let p50 = |k: Kind| summary(&hists[k.index()])[0] as f64;
    let floor = p50(Kind::Shm);
    let mut t = Table::new(&[
        "transport",
        "p50",
        "p90",
        "p99",
        "p99.9",
        "max",
        "p50 vs floor",
    ]);
    for k in Kind::ALL {
        let h = &hists[k.index()];
        let s = summary(h);
        let mut row = vec![k.label().to_string()];
        if h.is_empty() {
            row.extend(std::iter::repeat_n("n/a".to_string(), 6));
        } else {
            row.extend(s.iter().map(|&v| fmt_ns(v as f64)));
            row.push(fmt_ratio(ratio(s[0] as f64, floor)));
        }
        t.row(row);
    }
    let targets = vec![
        Target::new(
            "iceoryx2 polling p50 / spin floor p50",
            ratio(p50(Kind::IoxPoll), floor),
            Bound::AtMost(6.0),
        ),
        Target::new(
            "Unix socket p50 / iceoryx2 polling p50",
            ratio(p50(Kind::Unix), p50(Kind::IoxPoll)),
            Bound::AtLeast(5.0),
        ),
    ];
    (t.render(), targets)
}

/// The hidden peer's arguments.
#[derive(clap::Args, Debug)]
pub struct PeerArgs {
    #[arg(long)]
    pub namespace: String,
    #[arg(long)]
    pub shm_fd: i32,
    #[arg(long)]
    pub unix_fd: i32,
    #[arg(long)]
    pub udp_port: u16,
    #[arg(long)]
    pub core: usize,
    #[arg(long, default_value_t = 0)]
    pub priority: u8,
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
}

/// The peer process: sets up its ends, says `ready udp=<port>`, then serves `run <kind> <n>`
/// blocks (answering `done <kind> <n>`) until `quit` or the end of its input.
pub fn peer_main(a: &PeerArgs) -> Result<()> {
    let timeout = Duration::from_millis(a.timeout_ms);
    let names = ServiceNames::new(&a.namespace).map_err(|e| anyhow!("{e}"))?;
    apply_rt(a.core, a.priority, "latency peer");
    let ports = IoxPorts::peer(&names)?;
    let board = BoardLink::peer(&names)?;
    let region = ShmRegion::open(a.shm_fd)?;
    let shm = region.peer();
    // SAFETY: the descriptor was inherited from the parent for this purpose and is used once.
    let unix = UnixLink::new(unsafe { UnixStream::from_raw_fd(a.unix_fd) }, timeout)?;
    let udp = UdpSocket::bind("127.0.0.1:0").context("cannot bind a UDP socket on 127.0.0.1")?;
    udp.connect(("127.0.0.1", a.udp_port))
        .context("cannot connect the UDP socket")?;
    let port = udp.local_addr()?.port();
    let udp = UdpLink::new(udp, timeout)?;
    let mut stdout = std::io::stdout().lock();
    writeln!(stdout, "ready udp={port}")?;
    stdout.flush()?;
    for line in std::io::stdin().lock().lines() {
        let line = line.context("cannot read a command")?;
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.as_slice() {
            ["run", slug, n] => {
                let kind =
                    Kind::from_slug(slug).ok_or_else(|| anyhow!("unknown transport {slug:?}"))?;
                let n: usize = n
                    .parse()
                    .with_context(|| format!("bad count in {line:?}"))?;
                match kind {
                    Kind::Shm => link::pong_block(&shm, n, timeout),
                    Kind::IoxPoll => link::pong_block(&IoxPoll(&ports), n, timeout),
                    Kind::IoxBoard => link::pong_block(&board, n, timeout),
                    Kind::IoxListener => link::pong_block(&IoxListen(&ports), n, timeout),
                    Kind::IoxWaitSet => {
                        link::with_waitset(&ports, |l| link::pong_block(l, n, timeout))
                    }
                    Kind::Unix => link::pong_block::<UnixLink>(&unix, n, timeout),
                    Kind::Udp => link::pong_block::<UdpLink>(&udp, n, timeout),
                    Kind::Crossbeam => Err(anyhow!("the crossbeam series runs in the parent")),
                }
                .with_context(|| format!("serving {}", kind.label()))?;
                writeln!(stdout, "done {slug} {n}")?;
                stdout.flush()?;
            }
            ["quit"] => break,
            _ => bail!("unknown command {line:?}"),
        }
    }
    Ok(())
}

/// Where `peer_main`'s errors go: a line the parent reads, and stderr (its log).
pub fn report_peer_error(e: &anyhow::Error) {
    let msg = format!("{e:#}").replace('\n', " / ");
    println!("error {msg}");
    eprintln!("chaosd-bench latency peer: error: {e:#}");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(p50_ns: u64) -> Histogram<u64> {
        let mut h = histogram();
        h.record_n(p50_ns, 1000).unwrap();
        h
    }

    #[test]
    fn ratios_to_the_floor_and_the_targets() {
        // floor 200 ns, iceoryx2 polling 1 µs (5×), Unix socket 6 µs (6× polling): both met.
        let mut hists: Vec<Histogram<u64>> = Kind::ALL.iter().map(|_| histogram()).collect();
        hists[Kind::Shm.index()] = filled(200);
        hists[Kind::IoxPoll.index()] = filled(1_000);
        hists[Kind::Unix.index()] = filled(6_000);
        let (text, targets) = table(&hists);
        assert!(
            text.contains("| shared-memory spin flag (floor) | 200 ns |"),
            "{text}"
        );
        assert!(text.contains("| 1.00× |"), "{text}");
        assert!(text.contains("| 5.00× |"), "{text}");
        assert!(text.contains("| 30.0× |"), "{text}");
        assert!(text.contains("| UDP over 127.0.0.1 | n/a |"), "{text}");
        assert!(targets.iter().all(|t| t.met()), "{targets:?}");
        assert!((targets[0].value - 5.0).abs() < 0.02 && (targets[1].value - 6.0).abs() < 0.02);

        // iceoryx2 polling 1.4 µs: 7× the floor (missed) and the socket only 4.3× slower (missed).
        hists[Kind::IoxPoll.index()] = filled(1_400);
        let (_, targets) = table(&hists);
        assert!(targets.iter().all(|t| !t.met()), "{targets:?}");

        // No floor measured: no ratio can be claimed.
        hists[Kind::Shm.index()] = histogram();
        let (text, targets) = table(&hists);
        assert!(!targets[0].met());
        assert!(
            text.contains("| shared-memory spin flag (floor) | n/a |"),
            "{text}"
        );
    }

    #[test]
    fn slugs_round_trip() {
        for k in Kind::ALL {
            assert_eq!(Kind::from_slug(k.slug()), Some(k));
            assert_eq!(Kind::ALL[k.index()], k);
        }
        assert_eq!(Kind::from_slug("carrier-pigeon"), None);
        assert!(unique_namespace("x").len() <= protocol::MAX_NAMESPACE_LEN);
        assert!(protocol::validate_namespace(&unique_namespace("lat")).is_ok());
    }
}
