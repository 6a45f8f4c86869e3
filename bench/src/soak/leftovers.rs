//! What a soak may not leave behind: processes, iceoryx2 services, nodes and files.
//!
//! iceoryx2 keeps a service's static config under its root directory (`/tmp/iceoryx2/services`)
//! and its dynamic state and data segments in POSIX shared memory (`/dev/shm/iox2_…`), named
//! after the service's hash; each node has a directory named after its id. A process that
//! is SIGKILLed cannot remove its own; chaosd's answer is that every node creation and the
//! daemon's sweep (`cleanup_every_s`) remove dead nodes' resources. So the soak records, while
//! the system runs, the hashes of its namespace's services and the ids of every node its
//! processes ever created, and after the clean stop at the end checks that none of them is
//! still listed by iceoryx2 or present as a file, and that no process runs with its config.

use anyhow::Result;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::{ipc, CallbackProgression, Node, NodeState, SemanticString};
use iceoryx2::service::Service;
use std::collections::BTreeSet;
use std::path::Path;

/// Names and ids seen during the run.
#[derive(Default, Debug)]
pub struct Tracked {
    pub services: BTreeSet<String>,
    pub nodes: BTreeSet<u128>,
    pub pids: BTreeSet<u32>,
    /// CLOCK_MONOTONIC seconds when the soak started: older ids are someone else's.
    pub since_s: u32,
    /// Node ids whose pid iceoryx2 and [`id_origin`] read differently (should stay 0).
    pub layout_mismatches: usize,
}

fn config() -> iceoryx2::config::Config {
    // The same explicit default config every chaosd process uses (`protocol::node`).
    iceoryx2::config::Config::default()
}

/// (name, hash) of every service whose name starts with `prefix`.
fn services(prefix: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let _ = ipc::Service::list(&config(), |s| {
        let name = s.static_details.name().as_str().to_string();
        if name.starts_with(prefix) {
            out.push((name, s.static_details.service_hash().to_string()));
        }
        CallbackProgression::Continue
    });
    out
}

/// (id, pid, state) of every node created by one of `pids`.
fn nodes(pids: &BTreeSet<u32>) -> Vec<(u128, u32, &'static str)> {
    let mut out = Vec::new();
    let _ = Node::<ipc::Service>::list(&config(), |n| {
        let (id, state) = match &n {
            NodeState::Alive(v) => (*v.id(), "alive"),
            NodeState::Dead(v) => (*v.id(), "dead"),
            NodeState::Inaccessible(id) => (*id, "inaccessible"),
            NodeState::Undefined(id) => (*id, "undefined"),
        };
        if let Ok(pid) = id.pid::<ipc::Service>() {
            let pid = pid.value() as u32;
            if pids.contains(&pid) {
                out.push((id.value(), pid, state));
            }
        }
        CallbackProgression::Continue
    });
    out
}

/// The creating process and the creation time (CLOCK_MONOTONIC seconds) of an iceoryx2 id.
///
/// iceoryx2 0.10 builds every node, port and service id as a `UniqueSystemId`, a `repr(C)`
/// {seconds, nanoseconds, pid, counter} read as one little-endian u128, and names the files of
/// ports, connections and dynamic service state after those ids. `UniqueNodeId::pid` is the
/// official reading for nodes; [`Tracked::note`] checks this one agrees with it.
pub fn id_origin(id: u128) -> (u32, u32) {
    (((id >> 64) & 0xffff_ffff) as u32, (id & 0xffff_ffff) as u32)
}

/// Decimal iceoryx2 ids (20 digits or more) in a file name.
fn ids_in(name: &str) -> impl Iterator<Item = u128> + '_ {
    name.split(|c: char| !c.is_ascii_digit())
        .filter(|t| t.len() >= 20)
        .filter_map(|t| t.parse::<u128>().ok())
}

/// CLOCK_MONOTONIC seconds now.
pub fn monotonic_s() -> u32 {
    (protocol::monotonic_ns() / 1_000_000_000) as u32
}

impl Tracked {
    /// Whether an iceoryx2 file is one of ours: named after one of our services, or after an
    /// id that one of our processes created since the soak started.
    fn owns(&self, name: &str) -> bool {
        if !name.starts_with("iox2_") {
            return false;
        }
        if self.services.iter().any(|h| name.contains(h.as_str())) {
            return true;
        }
        ids_in(name).any(|id| {
            let (pid, secs) = id_origin(id);
            self.pids.contains(&pid) && secs + 1 >= self.since_s
        })
    }

    /// Adds what exists now.
    pub fn note(&mut self, prefix: &str) {
        for (_, hash) in services(prefix) {
            self.services.insert(hash);
        }
        for (id, pid, _) in nodes(&self.pids) {
            if id_origin(id).0 != pid {
                self.layout_mismatches += 1;
            }
            self.nodes.insert(id);
        }
    }

    /// Everything left: one line per leftover.
    pub fn leftovers(&self, prefix: &str, config_path: &Path) -> Result<Vec<String>> {
        let mut left = Vec::new();
        for (name, hash) in services(prefix) {
            left.push(format!("iceoryx2 service {name} ({hash}) still exists"));
        }
        for (id, pid, state) in nodes(&self.pids) {
            left.push(format!(
                "iceoryx2 node {id} of pid {pid} ({state}) still exists"
            ));
        }
        let root = String::from_utf8_lossy(config().global.root_path().as_bytes()).to_string();
        for dir in [root.as_str(), "/dev/shm"] {
            walk(Path::new(dir), &mut |p| {
                let Some(name) = p.file_name().map(|n| n.to_string_lossy().to_string()) else {
                    return;
                };
                if self.owns(&name) {
                    left.push(format!("file {} remains", p.display()));
                }
            });
        }
        let cfg = config_path.to_string_lossy().to_string();
        if let Ok(rd) = std::fs::read_dir("/proc") {
            for e in rd.flatten() {
                let Some(pid) = e.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
                    continue;
                };
                if pid == std::process::id() {
                    continue;
                }
                let cmd = std::fs::read(e.path().join("cmdline")).unwrap_or_default();
                let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
                if cmd.contains(&cfg) {
                    left.push(format!("process {pid} still runs: {}", cmd.trim()));
                }
            }
        }
        Ok(left)
    }
}

fn walk(dir: &Path, f: &mut impl FnMut(&Path)) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        f(&p);
        if e.file_type().is_ok_and(|t| t.is_dir()) {
            walk(&p, f);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_node_and_its_service_are_found_and_gone_once_dropped() {
        let _g = crate::iox_test_lock();
        let ns = crate::latency::unique_namespace("leftovers");
        let names = protocol::ServiceNames::new(&ns).unwrap();
        let prefix = names.to_string();
        let mut t = Tracked {
            since_s: monotonic_s(),
            ..Default::default()
        };
        t.pids.insert(std::process::id());
        let cfg = Path::new("/nonexistent/soak-leftovers-test.toml");
        {
            let node = protocol::node("soak-leftover-test").unwrap();
            let svc = protocol::open_state_service(&node, &names).unwrap();
            let _publisher = svc.publisher_builder().create().unwrap();
            t.note(&prefix);
            assert_eq!(t.services.len(), 1, "{t:?}");
            assert!(!t.nodes.is_empty(), "{t:?}");
            assert_eq!(t.layout_mismatches, 0, "iceoryx2's id layout changed");
            let left = t.leftovers(&prefix, cfg).unwrap();
            let has = |what: &str| left.iter().any(|l| l.contains(what));
            assert!(has("iceoryx2 service chaosd/"), "{left:#?}");
            assert!(has("(alive) still exists"), "{left:#?}");
            assert!(has("file /dev/shm/iox2_"), "{left:#?}");
            assert!(has(".service remains"), "{left:#?}");
        }
        let left = t.leftovers(&prefix, cfg).unwrap();
        assert!(left.is_empty(), "{left:#?}");
    }

    #[test]
    fn ids_name_their_process() {
        // A node id seen on this machine: pid 16380, created at 11344 s of CLOCK_MONOTONIC.
        assert_eq!(id_origin(228969389968383830568519382084688), (16380, 11344));
        let name = "iox2_b9fc73e5c1f646968758453273c6c65cb372831b_237684789703573640497416121424_79228464674358518468573146192.connection";
        let ids: Vec<u128> = ids_in(name).collect();
        assert_eq!(ids.len(), 2);
        assert!(ids.iter().all(|&id| id_origin(id).0 == 16380));
    }
}
