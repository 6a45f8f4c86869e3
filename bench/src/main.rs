//! chaosd-bench: answers "how fast is this on my machine, and against what?" in one command.
//!
//! Every subcommand measures chaosd next to its alternatives in the same run, on pinned cores,
//! interleaved in short blocks, and reports ratios: absolute times on a shared VM are noisy,
//! ratios measured side by side are not. Each prints a markdown table and writes `.hgrm` files
//! and a percentile plot (PNG and SVG) under `--out`. Nothing here asserts a speed; the tests only
//! check the harness itself.
//!
//! * `latency`: state → command round trips over iceoryx2 and the alternatives (`latency`).
//! * `jitter`:  loop wake-up lateness per wait strategy, next to cyclictest (`jitter`).
//! * `e2e`:     the real daemon and plant processes at 1 to 10 kHz (`e2e`).
//! * `compute`: the control law, an RK4 step, a 300 s run and a Lyapunov pair (`compute`), and
//!   the robot model (FK + Jacobian + J̇q̇, RNEA, CRBA, ABA on the Panda) next to a naive
//!   implementation, the `k` crate and pinocchio (`model_timing`).
//! * `all`:     the four in a row, and one summary.
//! * `soak`:    the real daemon and plant for N seconds under injected faults; a verdict table,
//!   and a non-zero exit if anything was lost, not recovered or left behind (`soak`).
//!
//! `--book PATH` writes the tables of the run into a book page, between its markers (`book`).

mod ab;
mod book;
mod child;
mod commands;
mod compute;
mod cycle_plan;
mod cyclictest;
mod device;
mod e2e;
mod jitter;
mod latency;
mod model_timing;
mod monitor_cost;
mod naive;
mod naive_model;
mod pinocchio_run;
mod plan;
mod plants;
mod plot;
mod record_cost;
mod report;
mod soak;
mod spatial_timing;
mod stats;
mod tick;
mod timing;

/// Counts allocations (armed per thread, only around what is counted): the compute benchmark
/// reports the robot model's allocations per call with it.
#[global_allocator]
static ALLOCATOR: rt::alloc_count::Counting = rt::alloc_count::Counting;

/// Held by the unit tests that make iceoryx2 nodes in this process: the soak's leftover check
/// counts every node of a pid as its own, so it must not run while another test has one open.
#[cfg(test)]
fn iox_test_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

use anyhow::{bail, Result};
use clap::{Args, Parser, Subcommand};
use report::Output;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "chaosd-bench",
    version,
    about = "chaosd latency, jitter, end-to-end and compute benchmarks, side by side"
)]
struct Cli {
    /// Short runs (the whole `all` in about 3 minutes on 2 vCPUs), for a smoke test.
    #[arg(long, global = true)]
    quick: bool,
    /// Where the reports, .hgrm files and plots go (one directory per subcommand).
    #[arg(long, global = true, default_value = "out/bench")]
    out: PathBuf,
    /// After the run, write its tables into this book page, each into the block between
    /// `<!-- bench:NAME -->` and `<!-- /bench:NAME -->` of its name, under a line saying when
    /// and how it ran; the rest of the page stays as it is. Checked before the run; not written
    /// if a marker is wrong. The performance chapter: `all --book docs/performance.md`.
    #[arg(long, global = true, value_name = "PATH")]
    book: Option<PathBuf>,
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Round-trip latency between two pinned processes: iceoryx2 (polling, Listener, WaitSet),
    /// Unix socket, UDP, a crossbeam channel, and a shared-memory spin flag as the floor.
    Latency(LatencyArgs),
    /// Wake-up lateness of a fixed-rate loop at 1, 5 and 10 kHz per wait strategy, with and
    /// without SCHED_FIFO, next to cyclictest.
    Jitter(JitterArgs),
    /// The real chaosd and chaosd-plant processes at 1, 2, 5 and 10 kHz.
    E2e(E2eArgs),
    /// Control-law evaluation, RK4 step, a 300 s simulation and a Lyapunov pair, next to a naive
    /// implementation; the robot model on the Panda next to a naive one, `k` and pinocchio.
    Compute {
        /// Core to pin to.
        #[arg(long, default_value_t = 0)]
        core: usize,
        /// Read pinocchio's timings from this file (another run of
        /// scripts/pinocchio-timings/run.sh) instead of timing pinocchio in this run.
        #[arg(long, conflicts_with = "no_pinocchio")]
        pinocchio: Option<PathBuf>,
        /// The Python venv with pinocchio's wheel that timing it in this run uses (made and
        /// filled by scripts/pinocchio-timings/run.sh when absent).
        #[arg(long = "pinocchio-venv", default_value = pinocchio_run::DEFAULT_VENV)]
        pinocchio_venv: PathBuf,
        /// Leave pinocchio out (its rows then say so).
        #[arg(long = "no-pinocchio")]
        no_pinocchio: bool,
    },
    /// The Panda in position mode through chaosd-bridge and chaosd-fakebot, limiter on and off,
    /// on the demo's set-up (a minute; 20 s with --quick) and on one whose law asks more than the
    /// arm can do: the device's reflex stops, missed answers, tracking and residual.
    Device,
    /// What each plant costs its core, side by side: the Panda at 1 kHz on the kinematic plant,
    /// chaosd's rigid-body arm and MuJoCo (when chaosd-plant-mujoco is built): the plant's step
    /// per cycle, its lateness, the daemon's, tracking and MuJoCo's contact count.
    Plants {
        /// The MuJoCo row with mesh collisions loads this model (skipped if absent).
        #[arg(long, default_value = plants::DEFAULT_MESH_MODEL)]
        mujoco_model: PathBuf,
    },
    /// latency, jitter, e2e and compute in a row, with one summary file.
    All {
        /// SCHED_FIFO priority for latency and jitter, 1..=98 [default: the daemon's].
        #[arg(long, value_parser = clap::value_parser!(u8).range(1..=98))]
        priority: Option<u8>,
        /// Leave pinocchio out of `compute` (its rows then say so); CI does, as the C++
        /// harness's first build takes minutes.
        #[arg(long = "no-pinocchio")]
        no_pinocchio: bool,
    },
    /// The real daemon and plant for N seconds while faults are injected (kill -9, SIGSTOP, a
    /// CPU hog, a rogue publisher, request bursts); prints a verdict table and exits non-zero if
    /// data was lost, a fault went unnoticed or unrecovered, or anything was left behind.
    Soak(SoakArgs),
    /// This build's `compute` or `e2e` against another build's, interleaved round by round, as
    /// ratios: what a change costs, measured side by side (`scripts/ab-build REV` builds the
    /// other). Arguments after `--` go to both builds' benchmark.
    Ab {
        /// The other build's `chaosd-bench` binary (for e2e, its chaosd and chaosd-plant beside).
        #[arg(long, value_name = "BIN")]
        against: PathBuf,
        /// The benchmark compared.
        #[arg(long, value_enum, default_value = "compute")]
        what: ab::What,
        /// Rounds; each runs both builds once, in alternating order.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Passed to both builds' benchmark (e.g. `-- --rates 1000 --modes state`).
        #[arg(last = true)]
        args: Vec<String>,
    },
    /// The other end of `latency` (started by it).
    #[command(name = "__latency-peer", hide = true)]
    LatencyPeer(latency::PeerArgs),
}

#[derive(Args)]
struct LatencyArgs {
    /// Measured rounds (each runs one block per transport).
    #[arg(long)]
    rounds: Option<usize>,
    /// Round trips per block.
    #[arg(long)]
    round_trips: Option<usize>,
    /// SCHED_FIFO priority of both sides, 1..=98, or 0 for the normal scheduler [default: the
    /// daemon's].
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=98))]
    priority: Option<u8>,
    /// Space the round trips at this period (µs) instead of back to back: the floor at a loop
    /// rate (1000 = 1 kHz). Defaults to 5 rounds of 1000 round trips.
    #[arg(long, value_parser = clap::value_parser!(u64).range(10..=1_000_000))]
    pace_us: Option<u64>,
    /// How a paced sender waits for its next period.
    #[arg(long, default_value = "hybrid", requires = "pace_us")]
    wait: rt::WaitStrategy,
    /// The hybrid wait's spin window (µs) [default: the daemon's].
    #[arg(long, requires = "pace_us")]
    spin_us: Option<f64>,
}

#[derive(Args)]
struct JitterArgs {
    /// Measured rounds (each runs one block per configuration).
    #[arg(long)]
    rounds: Option<usize>,
    /// Length of one block, in ms.
    #[arg(long)]
    block_ms: Option<u64>,
    /// SCHED_FIFO priority of the "with SCHED_FIFO" runs, 1..=98 [default: the daemon's].
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=98))]
    priority: Option<u8>,
    /// Core the loops run on [default: the daemon's].
    #[arg(long)]
    core: Option<usize>,
}

#[derive(Args)]
struct E2eArgs {
    /// Seconds per rate.
    #[arg(long)]
    seconds: Option<f64>,
    /// Rates in Hz (comma-separated).
    #[arg(long, value_delimiter = ',')]
    rates: Option<Vec<f64>>,
    /// Modes (comma-separated): clock (free-running), phase (clock, phase-locked to the plant's
    /// stamps), pubsub (state-triggered over iceoryx2 pub-sub alone), state (state-triggered
    /// over iceoryx2 with the fast lane), udp (state-triggered through chaosd-bridge and
    /// chaosd-fakebot, the device beside the bridge), udp-free (the same, the device unpinned).
    /// Default: all six.
    #[arg(long, value_delimiter = ',')]
    modes: Option<Vec<E2eMode>>,
    /// How long the daemon and the plant poll without sleeping around an expected sample (µs):
    /// their `spin_us` [default: the config default].
    #[arg(long)]
    spin_us: Option<f64>,
}

#[derive(Args)]
struct SoakArgs {
    /// How long the fault phase runs (s), 5 to 86400.
    #[arg(long)]
    seconds: f64,
    /// Seed of the fault schedule: the same seed and length give the same faults.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Fault kinds to inject (comma-separated) [default: all].
    #[arg(long, value_delimiter = ',')]
    faults: Vec<soak::schedule::FaultKind>,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum E2eMode {
    Clock,
    Phase,
    State,
    Pubsub,
    Udp,
    UdpFree,
}

fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    format!(
        "cargo run --release -p bench --bin chaosd-bench -- {}",
        args.join(" ")
    )
}

fn latency_opts(quick: bool, a: &LatencyArgs) -> Result<latency::Options> {
    let mut o = latency::Options::new(quick);
    if let Some(us) = a.pace_us {
        let spin_us = a
            .spin_us
            .unwrap_or(daemon::config::DaemonConfig::default().spin_us);
        if !(spin_us.is_finite() && (0.0..=1e6).contains(&spin_us)) {
            bail!("--spin-us must be between 0 and 1000000");
        }
        o.pace = Some(latency::link::Pace {
            period_ns: us * 1000,
            wait: a.wait,
            spin_ns: (spin_us * 1000.0) as u64,
        });
        o.rounds = 5;
        o.round_trips = 1000;
    }
    if let Some(r) = a.rounds {
        o.rounds = r;
    }
    if let Some(n) = a.round_trips {
        o.round_trips = n;
    }
    if o.rounds == 0 || o.round_trips == 0 {
        bail!("--rounds and --round-trips must be at least 1");
    }
    if let Some(p) = a.priority {
        o.priority = p;
    }
    Ok(o)
}

fn jitter_opts(quick: bool, a: &JitterArgs) -> Result<jitter::Options> {
    let mut o = jitter::Options::new(quick);
    if let Some(r) = a.rounds {
        o.rounds = r;
    }
    if let Some(ms) = a.block_ms {
        o.block = std::time::Duration::from_millis(ms);
    }
    if let Some(p) = a.priority {
        o.priority = p;
    }
    if let Some(c) = a.core {
        o.core = c;
    }
    o.validate()?;
    Ok(o)
}

fn e2e_opts(quick: bool, a: &E2eArgs) -> Result<e2e::Options> {
    let mut o = e2e::Options::new(quick);
    if let Some(s) = a.seconds {
        o.seconds = s;
    }
    if let Some(r) = &a.rates {
        o.rates = r.clone();
    }
    o.spin_us = a.spin_us;
    if let Some(m) = &a.modes {
        o.modes = m
            .iter()
            .map(|m| match m {
                E2eMode::Clock => e2e::result::Mode::Clock,
                E2eMode::Phase => e2e::result::Mode::Phase,
                E2eMode::State => e2e::result::Mode::State,
                E2eMode::Pubsub => e2e::result::Mode::PubSub,
                E2eMode::Udp => e2e::result::Mode::Udp,
                E2eMode::UdpFree => e2e::result::Mode::UdpFree,
            })
            .collect();
    }
    o.validate()?;
    Ok(o)
}

fn all(
    quick: bool,
    out: &Path,
    priority: Option<u8>,
    pinocchio: &pinocchio_run::Source,
    command: &str,
    book: Option<&book::Book>,
) -> Result<Output> {
    let mut lat = latency::Options::new(quick);
    let mut jit = jitter::Options::new(quick);
    if let Some(p) = priority {
        lat.priority = p;
        jit.priority = p;
    }
    jit.validate()?;
    let parts = [
        ("latency", latency::run(&lat, out, command)),
        ("jitter", jitter::run(&jit, out, command)),
        ("e2e", e2e::run(&e2e::Options::new(quick), out, command)),
        ("compute", compute::run(quick, 0, pinocchio, out, command)),
    ];
    let mut text = String::new();
    let mut tables = Vec::new();
    let mut failed = Vec::new();
    for (name, r) in parts {
        match r {
            Ok(o) => {
                text.push_str(&o.text);
                tables.extend(o.tables);
            }
            Err(e) => {
                text.push_str(&format!("## {name}\n\n**failed**: {e:#}\n"));
                failed.push(name);
            }
        }
        text.push('\n');
    }
    std::fs::create_dir_all(out)?;
    std::fs::write(out.join("summary.md"), &text)?;
    if !failed.is_empty() {
        print!("{text}");
        // The parts that ran still go into the book; the failed ones leave their blocks.
        match book.map(|b| b.write(&tables)) {
            Some(Ok(said)) => eprintln!("chaosd-bench: book: {said}"),
            Some(Err(e)) => eprintln!("chaosd-bench: error: {e:#}"),
            None => {}
        }
        bail!(
            "{} failed (see above and {}/summary.md)",
            failed.join(", "),
            out.display()
        );
    }
    Ok(Output { text, tables })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Cmd::LatencyPeer(a) = &cli.command {
        return match latency::peer_main(a) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                latency::report_peer_error(&e);
                ExitCode::FAILURE
            }
        };
    }
    // Ctrl-C stops between blocks, so children are stopped and iceoryx2 resources released.
    rt::signal::install();
    let command = command_line();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let book = cli.book.clone().map(|path| book::Book {
        path,
        command: book::command(&args),
    });
    // The page first: a wrong marker should cost a second, not the run.
    if let Some(page) = &book {
        match page.check() {
            Err(e) => {
                eprintln!("chaosd-bench: error: {e:#}");
                return ExitCode::FAILURE;
            }
            Ok(missing) if !missing.is_empty() => eprintln!(
                "chaosd-bench: warning: {} has no block for {}, which it should carry",
                page.path.display(),
                missing.join(", ")
            ),
            Ok(_) => {}
        }
    }
    let t0 = Instant::now();
    let (quick, out) = (cli.quick, cli.out.as_path());
    let result = match &cli.command {
        Cmd::Latency(a) => latency_opts(quick, a).and_then(|o| latency::run(&o, out, &command)),
        Cmd::Jitter(a) => jitter_opts(quick, a).and_then(|o| jitter::run(&o, out, &command)),
        Cmd::E2e(a) => e2e_opts(quick, a).and_then(|o| e2e::run(&o, out, &command)),
        Cmd::Compute {
            core,
            pinocchio,
            pinocchio_venv,
            no_pinocchio,
        } => {
            let source = match (pinocchio, no_pinocchio) {
                (_, true) => pinocchio_run::Source::Off,
                (Some(f), false) => pinocchio_run::Source::File(f.clone()),
                (None, false) => pinocchio_run::Source::Now {
                    venv: pinocchio_venv.clone(),
                },
            };
            compute::run(quick, *core, &source, out, &command)
        }
        Cmd::Device => device::run(quick, out, &command),
        Cmd::Plants { mujoco_model } => plants::run(quick, mujoco_model, out, &command),
        Cmd::Ab {
            against,
            what,
            rounds,
            args,
        } => ab::run(
            &ab::Ab {
                against,
                what: *what,
                args,
                rounds: *rounds,
            },
            quick,
            out,
        ),
        Cmd::All {
            priority,
            no_pinocchio,
        } => {
            let pinocchio = if *no_pinocchio {
                pinocchio_run::Source::Off
            } else {
                pinocchio_run::Source::Now {
                    venv: pinocchio_run::DEFAULT_VENV.into(),
                }
            };
            all(quick, out, *priority, &pinocchio, &command, book.as_ref())
        }
        Cmd::Soak(a) => soak::run(
            &soak::schedule::Options {
                seconds: a.seconds,
                seed: a.seed,
                faults: a.faults.clone(),
            },
            out,
            &command,
        ),
        Cmd::LatencyPeer(_) => unreachable!("handled above"),
    };
    let result = result.and_then(|o| {
        print!("{}", o.text);
        match &book {
            Some(b) => b.write(&o.tables).map(|said| format!("; book: {said}")),
            None => Ok(String::new()),
        }
    });
    match result {
        Ok(said) => {
            eprintln!(
                "chaosd-bench: done in {:.1} s; files under {}{said}",
                t0.elapsed().as_secs_f64(),
                out.display()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("chaosd-bench: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
