//! A minimal bridge: copy this file, replace `Driver` with your robot's API, keep the rest.
//! Run it like chaosd-plant (`cargo run --release -p plant --example bridge_template --
//! --config my.toml`) next to `chaosd run --config my.toml`. The loop, iceoryx2, timing,
//! histograms and fault handling come from `plant::run`; a bridge only moves numbers.

use clap::Parser;
use plant::app::{self, PlantArgs};
use plant::{Actuation, Plant, PlantError};
use protocol::StateSample;

/// Stand-in for your robot's driver: velocity in, encoders out (it integrates, so this runs).
struct Driver {
    q: [f64; 3],  // encoders
    qd: [f64; 3], // the velocity command
}

impl Driver {
    fn command_velocity(&mut self, qd: &[f64; 3]) -> std::io::Result<()> {
        self.qd = *qd;
        Ok(())
    }
    fn read_encoders(&mut self, dt: f64) -> std::io::Result<([f64; 3], [f64; 3])> {
        self.q
            .iter_mut()
            .zip(self.qd)
            .for_each(|(q, qd)| *q += qd * dt);
        Ok((self.q, self.qd))
    }
}

struct Bridge {
    driver: Driver,
    /// The velocity reference sent last: this robot takes velocities, chaosd sends q̈.
    qd_ref: [f64; 3],
    period: f64,
}

impl Plant for Bridge {
    fn n(&self) -> usize {
        3
    }
    fn flags(&self) -> u32 {
        0 // real hardware: not SIMULATED
    }
    fn activate(&mut self) -> Result<(), PlantError> {
        Ok(()) // power up, enable drives, open the connection
    }
    fn write(&mut self, a: Actuation<'_>) -> Result<(), PlantError> {
        match a {
            Actuation::Accelerate {
                qdd, qddd, since, ..
            } => {
                let mid = since + 0.5 * self.period; // integrate q̈ over one period into q̇_ref
                for j in 0..3 {
                    self.qd_ref[j] += (qdd[j] + qddd[j] * mid) * self.period;
                }
            }
            // With `[command] mode = "velocity"` (a `[robot]` set-up) the daemon integrates,
            // limits and sends q̇_r itself: pass it on.
            Actuation::Velocity { qd, .. } => self.qd_ref.copy_from_slice(&qd[..3]),
            Actuation::Hold | Actuation::Brake => self.qd_ref = [0.0; 3],
            // This robot takes no positions or torques; the handshake refuses such a daemon
            // before it sends one (declare what yours takes in your plant's set-up).
            Actuation::Position { .. } | Actuation::Torque { .. } => {
                return Err(PlantError::Fault {
                    what: "this robot takes velocity commands only",
                    source: None,
                })
            }
        }
        let sent = self.driver.command_velocity(&self.qd_ref);
        sent.map_err(|e| PlantError::Unavailable {
            what: "velocity command not delivered",
            source: Some(e.into()),
        })
    }
    fn read(&mut self, elapsed: f64, out: &mut StateSample) -> Result<(), PlantError> {
        let read = self.driver.read_encoders(elapsed);
        let (q, qd) = read.map_err(|e| PlantError::Fault {
            what: "encoder read failed",
            source: Some(e.into()),
        })?;
        out.n = 3;
        out.q[..3].copy_from_slice(&q);
        out.qd[..3].copy_from_slice(&qd);
        self.qd_ref = qd; // follow the measured rates, so the next command starts from them
        Ok(())
    }
    fn deactivate(&mut self) {
        let _ = self.driver.command_velocity(&[0.0; 3]); // stop, disable drives
    }
}

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    plant: PlantArgs, // the standard flags; add your own (a device address, ...) next to it
}

fn main() -> std::process::ExitCode {
    app::serve("bridge-template", &Args::parse().plant, |launch| {
        anyhow::ensure!(launch.system.n() == 3, "this bridge drives a 3-joint arm");
        let q = launch.system.initial_state::<3>().q.into();
        Ok(Bridge {
            driver: Driver { q, qd: [0.0; 3] },
            qd_ref: [0.0; 3],
            period: 1.0 / launch.plant.rate_hz,
        })
    })
}
