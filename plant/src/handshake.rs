//! The plant's half of the handshake (`protocol::handshake`), on its own thread, off the loop.
//!
//! This thread publishes the plant's [`ArmInfo`] on `chaosd/<ns>/plant/info` (bound to this
//! start's `plant_id`) and reads the daemon's from `chaosd/<ns>/daemon/info`. When a daemon
//! describes another arm, it says so (naming both sides), asks the loop to stop, and
//! [`crate::run::run`] then returns the refusal as its error, so the process exits non-zero. The
//! plant loop itself does nothing for the handshake.

use anyhow::{anyhow, Result};
use control::System;
use protocol::handshake::{Exchange, Side};
use protocol::{mismatch, ArmInfo, ServiceNames};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// How often the thread looks for a daemon's description.
const POLL: Duration = Duration::from_millis(2);
/// How long a refusing plant keeps its description up before it stops.
const GRACE: Duration = Duration::from_millis(300);

/// The description of the arm in `system` (the file's `[robot]`).
pub fn describe(system: &System) -> ArmInfo {
    rt::robot::arm_info(system, 0)
}

/// The running handshake thread.
pub struct Handshake {
    running: Arc<AtomicBool>,
    refusal: Arc<Mutex<Option<String>>>,
    thread: Option<JoinHandle<()>>,
}

impl Handshake {
    /// Publishes `mine` (with `plant_id` as its instance id) and starts watching for a daemon.
    /// Returns once the description is published.
    pub fn start(
        names: &ServiceNames,
        mut mine: ArmInfo,
        plant_id: u64,
        avoid_core: Option<usize>,
    ) -> Result<Self> {
        mine.instance_id = plant_id;
        let names = names.clone();
        let running = Arc::new(AtomicBool::new(true));
        let refusal = Arc::new(Mutex::new(None));
        let (run, said) = (running.clone(), refusal.clone());
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel::<Result<()>>(1);
        let thread = std::thread::Builder::new()
            .name("plant-handshake".into())
            .spawn(move || {
                rt::setup::avoid_core(avoid_core);
                let exchange = match Exchange::open(Side::Plant, &names, mine) {
                    Ok(x) => {
                        let _ = ready_tx.send(Ok(()));
                        x
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(anyhow!(e)));
                        return;
                    }
                };
                while run.load(Ordering::Relaxed) {
                    // Also hands our description to a daemon that joined since.
                    let newest = exchange.newest_peer();
                    if let Some(why) = newest.and_then(|d| mismatch(names.namespace(), &mine, &d)) {
                        if let Ok(mut g) = said.lock() {
                            *g = Some(why);
                        }
                        // Stay a moment, so that a daemon that has just joined still gets our
                        // description and can say why it refuses too.
                        for _ in 0..(GRACE.as_millis() / POLL.as_millis()) {
                            let _ = exchange.newest_peer();
                            std::thread::sleep(POLL);
                        }
                        rt::signal::request_stop();
                        return;
                    }
                    std::thread::sleep(POLL);
                }
            })?;
        let mut hs = Self {
            running,
            refusal,
            thread: Some(thread),
        };
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(hs),
            Ok(Err(e)) => {
                hs.stop();
                Err(e)
            }
            Err(_) => Err(anyhow!("the handshake thread ended before it started")),
        }
    }

    /// Stops the thread; returns the refusal if a mismatched daemon was seen.
    pub fn stop(&mut self) -> Option<String> {
        self.running.store(false, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.refusal.lock().ok().and_then(|g| g.clone())
    }
}

impl Drop for Handshake {
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_description_follows_the_config() {
        let mut c = control::Config::preset("paper").unwrap();
        c.planar_mut().unwrap().arm.links = vec![1.0, 0.5, 0.25, 0.125];
        let d = describe(&System::Planar(c));
        assert_eq!((d.n, d.kind), (4, protocol::handshake::KIND_FIXED));
        assert_eq!(&d.links[..4], &[1.0, 0.5, 0.25, 0.125]);
        let f = describe(&rt::robot::preset("paper-floating").unwrap());
        assert_eq!(f.kind, protocol::handshake::KIND_FLOATING);
        assert!(f.base_mass > 0.0);
        let p = describe(&rt::robot::preset("panda").unwrap());
        assert_eq!((p.n, p.kind), (7, protocol::handshake::KIND_CHAIN));
        assert_eq!(p.robot_name(), "panda (panda_link0 → panda_link8)");
    }
}
