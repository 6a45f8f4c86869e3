//! The daemon's half of the handshake (`protocol::handshake`), on its own thread, off the loop.
//!
//! This thread publishes the daemon's [`ArmInfo`] on `chaosd/<ns>/daemon/info`, reads the
//! plant's from `chaosd/<ns>/plant/info`, and judges each plant start (each `plant_id`) once. The
//! verdict reaches the loop as a [`LoopRequest::Plant`] through the same bounded channel the
//! control service uses, taken between two ticks; the tick itself only compares the state's
//! `plant_id` with the agreed one. Until a plant is agreed to, its states are ignored, so the
//! daemon stays in HOLD and never sends a mismatched plant a RUN command. A refusal is said once
//! on stderr and kept for `chaosctl status` ([`Refusal`]). A restarted plant has a new id and is
//! judged again.

use crate::telemetry::LoopRequest;
use anyhow::{anyhow, Result};
use control::System;
use protocol::handshake::{Exchange, Side};
use protocol::{mismatch, ArmInfo, ServiceNames};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// How often the thread looks for a plant's description.
const POLL: Duration = Duration::from_millis(2);

/// Why the current plant is refused, if it is (shown by `chaosctl status`).
pub type Refusal = Arc<Mutex<Option<String>>>;

/// The description of the arm in `system`, for the process with `instance_id`.
pub fn describe(system: &System, instance_id: u64) -> ArmInfo {
    rt::robot::arm_info(system, instance_id)
}

/// Judges each plant start once.
pub struct Judge {
    namespace: String,
    mine: ArmInfo,
    judged: Option<u64>,
    refused_before: bool,
}

/// A verdict on one plant start.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    pub plant_id: u64,
    /// `None`: agreed. Otherwise the refusal, naming both sides.
    pub refusal: Option<String>,
}

impl Judge {
    pub fn new(namespace: &str, mine: ArmInfo) -> Self {
        Self {
            namespace: namespace.to_string(),
            mine,
            judged: None,
            refused_before: false,
        }
    }

    /// A verdict for a plant start not judged before; `None` for one already judged.
    pub fn judge(&mut self, plant: &ArmInfo) -> Option<Verdict> {
        if self.judged == Some(plant.instance_id) {
            return None;
        }
        self.judged = Some(plant.instance_id);
        Some(Verdict {
            plant_id: plant.instance_id,
            refusal: mismatch(&self.namespace, plant, &self.mine),
        })
    }
}

/// Starts the handshake thread; returns once the daemon's description is published. The thread
/// ends when `running` turns false or the loop's channel closes.
pub fn spawn(
    system: &System,
    names: &ServiceNames,
    params_tx: crossbeam::channel::Sender<LoopRequest>,
    running: Arc<AtomicBool>,
    loop_core: Option<usize>,
) -> Result<(JoinHandle<()>, Refusal)> {
    let mine = describe(system, protocol::new_instance_id());
    let names = names.clone();
    let refusal: Refusal = Arc::default();
    let shown = refusal.clone();
    let (ready_tx, ready_rx) = crossbeam::channel::bounded::<Result<()>>(1);
    let handle = std::thread::Builder::new()
        .name("chaosd-handshake".into())
        .spawn(move || {
            rt::setup::avoid_core(loop_core);
            let exchange = match Exchange::open(Side::Daemon, &names, mine) {
                Ok(x) => {
                    let _ = ready_tx.send(Ok(()));
                    x
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(anyhow!(e)));
                    return;
                }
            };
            let mut judge = Judge::new(names.namespace(), mine);
            let mut pending: Option<LoopRequest> = None;
            while running.load(Ordering::Relaxed) {
                // Also hands our description to a plant that joined since (a restart).
                let newest = exchange.newest_peer();
                if let Some(v) = newest.as_ref().and_then(|p| judge.judge(p)) {
                    pending = Some(report(&mut judge, &refusal, &v));
                }
                if let Some(r) = pending {
                    match params_tx.try_send(r) {
                        Ok(()) => pending = None,
                        Err(crossbeam::channel::TrySendError::Full(_)) => {}
                        Err(crossbeam::channel::TrySendError::Disconnected(_)) => return,
                    }
                }
                std::thread::sleep(POLL);
            }
        })?;
    match ready_rx.recv() {
        Ok(Ok(())) => Ok((handle, shown)),
        Ok(Err(e)) => {
            let _ = handle.join();
            Err(e)
        }
        Err(_) => Err(anyhow!("the handshake thread ended before it started")),
    }
}

/// Says a verdict once (stderr, status) and turns it into the loop's request.
fn report(judge: &mut Judge, refusal: &Refusal, v: &Verdict) -> LoopRequest {
    match &v.refusal {
        Some(why) => {
            eprintln!("chaosd: {why}; holding until a matching plant starts");
            judge.refused_before = true;
        }
        None if judge.refused_before => {
            judge.refused_before = false;
            eprintln!(
                "chaosd: plant {:?} is {}, as expected; controlling it",
                judge.namespace, judge.mine
            );
        }
        None => {}
    }
    if let Ok(mut g) = refusal.lock() {
        *g = v.refusal.clone();
    }
    LoopRequest::Plant {
        plant_id: v.plant_id,
        agreed: v.refusal.is_none(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::Config;

    fn planar(name: &str) -> System {
        System::Planar(Config::preset(name).unwrap())
    }

    #[test]
    fn each_plant_start_is_judged_once() {
        let daemon = describe(&planar("paper"), 1);
        let mut judge = Judge::new("ns", daemon);
        let mut four = Config::preset("paper").unwrap();
        four.planar_mut().unwrap().arm.links = vec![1.0; 4];
        let plant = describe(&System::Planar(four), 7);
        let v = judge.judge(&plant).unwrap();
        assert_eq!(v.plant_id, 7);
        assert_eq!(
            v.refusal.as_deref(),
            Some("plant \"ns\" is a 4-link fixed arm (links 1,1,1,1), daemon expects a 3-link fixed arm (links 1,1,1); refusing")
        );
        assert_eq!(judge.judge(&plant), None, "judged once");
        // The plant restarts with the daemon's arm: agreed.
        let plant = describe(&planar("paper"), 8);
        assert_eq!(judge.judge(&plant).unwrap().refusal, None);
    }

    #[test]
    fn floating_presets_describe_their_base() {
        let f = describe(&planar("paper-floating"), 1);
        assert_eq!(f.kind, protocol::handshake::KIND_FLOATING);
        let fixed = describe(&planar("paper"), 1);
        assert!(mismatch("x", &fixed, &f).unwrap().contains("floating arm"));
    }

    #[test]
    fn a_panda_daemon_refuses_a_planar_plant_and_another_chain_naming_both() {
        let panda = rt::robot::preset("panda").unwrap();
        let mut judge = Judge::new("lab", describe(&panda, 1));
        let why = judge
            .judge(&describe(&planar("paper"), 2))
            .unwrap()
            .refusal
            .unwrap();
        assert!(
            why.contains("3-link fixed arm (links 1,1,1)")
                && why.contains("7-joint panda (panda_link0 → panda_link8)"),
            "{why}"
        );
        let System::Spatial(mut short) = panda.clone() else {
            unreachable!("panda is spatial")
        };
        short.own_mut().robot.tip = Some("panda_link7".into());
        short.chain = rt::robot::load("panda", None, Some("panda_link7")).unwrap();
        let why = judge
            .judge(&describe(&System::Spatial(short), 3))
            .unwrap()
            .refusal
            .unwrap();
        assert!(
            why.contains("panda_link7") && why.contains("panda_link8"),
            "{why}"
        );
        assert_eq!(judge.judge(&describe(&panda, 4)).unwrap().refusal, None);
    }
}
