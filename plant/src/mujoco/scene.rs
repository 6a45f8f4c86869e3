//! The daemon's obstacles, followed live: `chaosctl obstacle add|rm` changes the daemon's spheres,
//! and MuJoCo's world must change with them, or the judge would count contacts against a scene
//! the controller no longer has (and miss the ones it added).
//!
//! A helper thread, off the loop's core, asks the daemon's control service for its obstacle
//! list a few times a second (the same `ObstacleList` request `chaosctl obstacle ls` sends) and
//! hands a changed list to the loop through a one-slot channel; the loop takes it between two
//! periods without waiting or allocating ([`Spheres`] is `Copy`). Without a daemon answering,
//! the scene stays as the set-up's.

use iceoryx2::prelude::*;
use protocol::control::{ControlRequest, ControlResponse, Op};
use protocol::ServiceNames;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// As many spheres as the daemon's law takes.
pub const MAX: usize = control::secondary::MAX_OBSTACLES;
/// How often the list is asked for.
const EVERY: Duration = Duration::from_millis(200);
/// How long one answer may take.
const ANSWER: Duration = Duration::from_millis(100);

/// A scene's spheres: centre and radius (m), the first `n` in use.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spheres {
    pub n: usize,
    pub s: [([f64; 3], f64); MAX],
}

impl Spheres {
    /// The spheres of a list (the first [`MAX`]).
    pub fn of(list: &[([f64; 3], f64)]) -> Self {
        let mut s = [([0.0; 3], 0.0); MAX];
        let n = list.len().min(MAX);
        s[..n].copy_from_slice(&list[..n]);
        Self { n, s }
    }

    pub fn used(&self) -> &[([f64; 3], f64)] {
        &self.s[..self.n]
    }

    /// The list `ObstacleList` answers: `[{"center": [x, y, z], "radius": r, …}, …]`; None if it
    /// is not a list of spheres (a planar daemon's discs, a malformed body).
    pub fn parse(body: &str) -> Option<Self> {
        let v: serde_json::Value = serde_json::from_str(body).ok()?;
        let rows = v.as_array()?;
        let mut list = Vec::with_capacity(rows.len());
        for r in rows {
            let c = r["center"].as_array()?;
            if c.len() != 3 {
                return None;
            }
            let at = [c[0].as_f64()?, c[1].as_f64()?, c[2].as_f64()?];
            let radius = r["radius"].as_f64()?;
            if !(at.iter().all(|x| x.is_finite()) && radius.is_finite() && radius > 0.0) {
                return None;
            }
            list.push((at, radius));
        }
        (list.len() <= MAX).then(|| Self::of(&list))
    }
}

/// The helper thread; stopped and joined on drop.
pub struct SceneSync {
    running: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl SceneSync {
    /// Follows the daemon in `names`' namespace from `start` on; changes arrive on the receiver.
    pub fn start(
        names: ServiceNames,
        start: Spheres,
        avoid_core: Option<usize>,
    ) -> std::io::Result<(Self, Receiver<Spheres>)> {
        let (tx, rx) = sync_channel(1);
        let running = Arc::new(AtomicBool::new(true));
        let run = running.clone();
        let thread = std::thread::Builder::new()
            .name("mujoco-scene".into())
            .spawn(move || {
                rt::setup::avoid_core(avoid_core);
                follow(&names, start, &tx, &run);
            })?;
        Ok((
            Self {
                running,
                thread: Some(thread),
            },
            rx,
        ))
    }
}

impl Drop for SceneSync {
    fn drop(&mut self) {
        self.running.store(false, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

type Client = iceoryx2::port::client::Client<ipc::Service, ControlRequest, (), ControlResponse, ()>;

fn follow(names: &ServiceNames, mut known: Spheres, tx: &SyncSender<Spheres>, run: &AtomicBool) {
    let Ok(node) = protocol::node("chaosd-plant-mujoco-scene") else {
        return;
    };
    let mut client: Option<Client> = None;
    while run.load(Ordering::Relaxed) {
        std::thread::sleep(EVERY);
        if client.is_none() {
            client = protocol::control::open_control_service(&node, names)
                .ok()
                .and_then(|s| s.client_builder().create().ok());
        }
        let Some(c) = &client else { continue };
        match ask(c) {
            Some(now) if now != known => match tx.try_send(now) {
                // The loop has not taken the last one yet: ask again next time.
                Err(TrySendError::Full(_)) => {}
                Err(TrySendError::Disconnected(_)) => return,
                Ok(()) => {
                    tracing::info!(
                        "MuJoCo: the daemon's obstacles changed: {} sphere(s) in MuJoCo's world now",
                        now.n
                    );
                    known = now;
                }
            },
            Some(_) => {}
            // The daemon went away (or answered oddly): reconnect next time.
            None => client = None,
        }
    }
}

/// One `ObstacleList` round trip.
fn ask(c: &Client) -> Option<Spheres> {
    let req = ControlRequest::new(std::process::id() as u64, Op::ObstacleList, "").ok()?;
    let pending = c.send_copy(req).ok()?;
    if pending.number_of_server_connections() == 0 {
        return None;
    }
    let deadline = Instant::now() + ANSWER;
    while Instant::now() < deadline {
        if let Ok(Some(r)) = pending.receive() {
            let r: ControlResponse = *r;
            return if r.is_ok() {
                Spheres::parse(r.body().ok()?)
            } else {
                None
            };
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_daemons_list_is_read_as_spheres_and_anything_else_is_not() {
        let body = r#"[{"number":1,"center":[0.1,-0.2,0.5],"radius":0.05,"margin":0.1},
                      {"number":2,"center":[0.3,0.0,0.4],"radius":0.03,"margin":0.1}]"#;
        let s = Spheres::parse(body).unwrap();
        assert_eq!(
            s.used(),
            &[([0.1, -0.2, 0.5], 0.05), ([0.3, 0.0, 0.4], 0.03)]
        );
        assert_eq!(Spheres::parse("[]").unwrap().n, 0);
        for bad in [
            r#"[{"center":[1.0,2.0],"radius":0.1}]"#,
            r#"[{"center":[1,2,3],"radius":-1}]"#,
            r#"{"center":[1,2,3]}"#,
            "not json",
        ] {
            assert_eq!(Spheres::parse(bad), None, "{bad}");
        }
    }
}
