//! chaosd-gateway: chaosd across hosts over Zenoh.
//!
//! `serve` runs on each host next to its daemons and bridges their iceoryx2 telemetry and control
//! services to a Zenoh network; `status`, `get`, `set`, `obstacle`, `dfc`, `hist`, `record`,
//! `resume`, `shutdown`, `watch` and `fleet` with `--remote ENDPOINT` reach them from anywhere on
//! that network (every local control command but `debug-stall`); `bench` measures the round trip
//! and the telemetry loss. Zenoh lives only in this binary: `chaosd` and `chaosd-plant` never link it,
//! and `chaosctl --remote …`, `chaosctl gateway` and `chaosctl fleet` run this program.
//! `main` only maps errors to exit codes (0 done, 1 refused, 2 bad usage, 3 no answer).

mod bench;
mod keys;
mod remote;
mod serve;
mod session;

use clap::{Args, Parser, Subcommand};
use client::online::{dfc_op, hist_op, pretty, ObstacleAction, RecordAction};
use protocol::Op;
use remote::{Fail, Remote, Target};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "chaosd-gateway",
    version,
    about = "chaosd across hosts: serve local daemons over Zenoh, or reach remote ones"
)]
struct Cli {
    /// A gateway's Zenoh endpoint (its --listen), e.g. tcp/10.0.0.5:7447: the network to reach.
    #[arg(long, global = true)]
    remote: Option<String>,
    /// Seconds to wait for an answer (or, for watch, between samples).
    #[arg(long, global = true, default_value_t = 3.0)]
    timeout: f64,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Serve this host's daemons on Zenoh (read-only unless --allow-changes).
    Serve(serve::ServeArgs),
    /// Mode, parameters, counters and latency of a remote daemon.
    Status {
        #[command(flatten)]
        target: Target,
        /// Print the daemon's raw JSON (with the gateway's host, namespace and access).
        #[arg(long)]
        json: bool,
    },
    /// The running configuration of a remote daemon, as TOML.
    Get {
        #[command(flatten)]
        target: Target,
    },
    /// Change a remote daemon's parameters, all or nothing: `set mu 1.5 tau 1.0`.
    Set {
        #[command(flatten)]
        target: Target,
        /// KEY VALUE pairs, as for `chaosctl set`.
        #[arg(required = true, num_args = 1.., allow_negative_numbers = true)]
        pairs: Vec<String>,
    },
    /// Add, remove or list a remote daemon's obstacles.
    Obstacle {
        #[command(flatten)]
        target: Target,
        #[command(subcommand)]
        action: ObstacleAction,
    },
    /// A remote daemon's delayed feedback on (from now) or off.
    Dfc {
        #[command(flatten)]
        target: Target,
        #[arg(value_parser = ["on", "off"])]
        state: String,
    },
    /// A remote daemon's latency percentiles since its start (or the last reset).
    Hist {
        #[command(flatten)]
        target: Target,
        /// Reset the histograms.
        #[arg(long)]
        reset: bool,
    },
    /// Record a remote daemon's state and command streams into its output directory.
    Record {
        #[command(flatten)]
        target: Target,
        #[command(subcommand)]
        action: RecordAction,
    },
    /// Take a remote daemon out of FAULT (refused when not in FAULT).
    Resume {
        #[command(flatten)]
        target: Target,
    },
    /// Stop a remote daemon cleanly.
    Shutdown {
        #[command(flatten)]
        target: Target,
    },
    /// A remote daemon's live telemetry, one line (or JSON object) per sample.
    Watch {
        #[command(flatten)]
        target: Target,
        #[arg(long)]
        json: bool,
        /// Stop after this many samples.
        #[arg(long)]
        count: Option<u64>,
    },
    /// Every controller the Zenoh network sees, one line each.
    Fleet(FleetArgs),
    /// Measure the remote status round trip and the telemetry loss.
    Bench(bench::BenchArgs),
}

#[derive(Args)]
struct FleetArgs {
    /// One JSON array instead of the table.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    // SAFETY: restoring the default SIGPIPE disposition before any thread starts (`| head`).
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Serve(a) => serve::run(a).map_err(|e| Fail::usage(format!("{e:#}"))),
        other => client_command(cli.remote.as_deref(), cli.timeout, other),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("chaosd-gateway: error: {}", f.msg);
            ExitCode::from(f.code)
        }
    }
}

fn client_command(remote: Option<&str>, timeout: f64, cmd: Command) -> Result<(), Fail> {
    let Some(endpoint) = remote else {
        return Err(Fail::usage(
            "give --remote ENDPOINT: the --listen endpoint of a gateway, e.g. tcp/127.0.0.1:7447",
        ));
    };
    let r = Remote::connect(endpoint, timeout)?;
    let body = match cmd {
        Command::Status { target, json } => {
            let (_, body) = r.request(&target, Op::Status, "")?;
            if json {
                body
            } else {
                client::online::human_status(&body)
            }
        }
        Command::Get { target } => r.request(&target, Op::GetConfig, "")?.1,
        Command::Set { target, pairs } => pretty(&r.request(&target, Op::Set, &pairs.join(" "))?.1),
        Command::Obstacle { target, action } => {
            let (op, args) = action.request();
            pretty(&r.request(&target, op, &args)?.1)
        }
        Command::Dfc { target, state } => pretty(&r.request(&target, dfc_op(&state), "")?.1),
        Command::Hist { target, reset } => pretty(&r.request(&target, hist_op(reset), "")?.1),
        Command::Record { target, action } => {
            let (op, args) = action.request();
            pretty(&r.request(&target, op, &args)?.1)
        }
        Command::Resume { target } => r.request(&target, Op::Resume, "")?.1,
        Command::Shutdown { target } => r.request(&target, Op::Shutdown, "")?.1,
        Command::Watch {
            target,
            json,
            count,
        } => {
            remote::watch(&r, &target, json, count)?;
            String::new()
        }
        Command::Fleet(a) => remote::fleet(&r, a.json)?,
        Command::Bench(a) => bench::run(&r, &a)?,
        Command::Serve(_) => unreachable!("handled in main"),
    };
    if !body.is_empty() {
        println!("{body}");
    }
    Ok(())
}
