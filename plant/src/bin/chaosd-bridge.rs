//! chaosd-bridge: the plant process for a device on the UDP protocol of `plant::udp` (for
//! example chaosd-fakebot). The loop, iceoryx2 and the reports are `plant::app`'s; this file only
//! adds the device's address.

use anyhow::{ensure, Context};
use clap::Parser;
use plant::app::{self, PlantArgs};
use plant::udp::bridge::{BridgeConfig, UdpBridge};
use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::Duration;

#[derive(Parser)]
#[command(
    name = "chaosd-bridge",
    version,
    about = "The chaosd plant process for a robot on the UDP device protocol (see plant/src/udp/mod.rs)"
)]
struct Args {
    #[command(flatten)]
    plant: PlantArgs,
    /// The device's address (where commands go).
    #[arg(long)]
    device: SocketAddr,
    /// The address this bridge receives states on.
    #[arg(long, default_value = "127.0.0.1:47001")]
    bind: SocketAddr,
    /// Wait this long for a state before counting the cycle as missed (ms; default 2 periods).
    #[arg(long = "timeout-ms")]
    timeout_ms: Option<f64>,
    /// Report the device lost after this much silence (ms).
    #[arg(long = "lost-after-ms", default_value_t = 100.0)]
    lost_after_ms: f64,
}

fn ms(name: &str, v: f64) -> anyhow::Result<Duration> {
    ensure!(
        v.is_finite() && (0.1..=60_000.0).contains(&v),
        "--{name} {v}: must be between 0.1 and 60000 ms"
    );
    Ok(Duration::from_secs_f64(v * 1e-3))
}

fn main() -> ExitCode {
    let args = Args::parse();
    app::main_with("chaosd-bridge", &args.plant, |l| {
        ensure!(
            args.bind != args.device,
            "--bind and --device are both {}",
            args.bind
        );
        let period_ms = 1e3 / l.plant.rate_hz;
        let cfg = BridgeConfig {
            bind: args.bind,
            device: args.device,
            timeout: ms("timeout-ms", args.timeout_ms.unwrap_or(2.0 * period_ms))?,
            lost_after: ms("lost-after-ms", args.lost_after_ms)?,
            period: Duration::from_secs_f64(1.0 / l.plant.rate_hz),
            wait: l.plant.wait,
            spin: Duration::from_secs_f64(l.plant.spin_us * 1e-6),
            loop_core: l.plant.core,
            interface: l.system.command_mode().code(),
        };
        let mut bridge = UdpBridge::new(l.system.n(), cfg);
        let summary = plant::run::run(&mut bridge, &l.plant, &l.arm(), l.duration);
        let c = bridge.counters;
        tracing::info!(
            "{} states, {} commands sent; {} timeouts, {} malformed, {} out of order, {} superseded; device lost {} times, restarted {} times",
            c.states, c.commands_sent, c.timeouts, c.malformed, c.out_of_order, c.superseded, c.device_lost, c.device_restarts
        );
        summary.context("the bridge stopped")
    })
}
