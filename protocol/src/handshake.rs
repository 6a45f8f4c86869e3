//! The handshake: each side says which arm it is built for, and a mismatched pair is refused.
//!
//! A 4-link plant and a 3-link daemon, or two 3-link arms with different link lengths, would
//! otherwise meet in silence: the daemon would reject every state (wrong size) and sit in HOLD
//! with no word why, or control the plant with the wrong model. So the plant publishes an
//! [`ArmInfo`] on `chaosd/<ns>/plant/info` and the daemon one on `chaosd/<ns>/daemon/info`. Both
//! services keep the newest sample as history, so a side that starts (or restarts) later still
//! sees it. Each side compares with [`mismatch`], which returns one line naming both sides; the
//! daemon then never runs that plant (it keeps HOLD), the plant exits with the message.
//!
//! [`ArmInfo`] deliberately has a type name **without** the wire version, and a layout that must
//! not change (pinned by a test): it is the one sample two builds of different wire versions
//! can still exchange, so that they can tell each other which versions they speak. Its arrays
//! are [`MAX_JOINTS`] long, so it changed with the joint capacity (6 → 7, wire version 4 → 5:
//! 192 → 216 bytes), and again when URDF chains joined the planar arms (version 6: the robot's
//! name and fingerprint, 288 bytes), and with the capacity again (7 → 12, wire version 9: 408
//! bytes, so that a torso and a 7-joint arm fit). Builds on either side of such a change cannot exchange it:
//! whichever starts second fails to open the info service (`IncompatibleTypes`) instead of naming
//! both versions.
//!
//! A URDF chain ([`KIND_CHAIN`]) is described by its name and a fingerprint of every number of
//! its model (`control::System::identity`): two processes that loaded different descriptions,
//! base or tip links, tool points or link radii are refused by name, so a Panda daemon never
//! drives a plant built for another chain.

use core::fmt::{self, Write as _};

use iceoryx2::node::Node;
use iceoryx2::port::update_connections::UpdateConnections as _;
use iceoryx2::prelude::ZeroCopySend;
use iceoryx2::service::port_factory::publish_subscribe;

use crate::names::ServiceNames;
use crate::qos::{open_pubsub, Channel, PubSubQos, ServiceError};
use crate::{MAX_JOINTS, MIN_JOINTS, WIRE_VERSION};

/// [`ArmInfo::kind`]: a fixed base.
pub const KIND_FIXED: u32 = 0;
/// [`ArmInfo::kind`]: a free-floating base.
pub const KIND_FLOATING: u32 = 1;
/// [`ArmInfo::kind`]: a serial chain from a robot description (URDF).
pub const KIND_CHAIN: u32 = 2;
/// Bytes of a chain's name kept in [`ArmInfo::robot`] (longer names are cut).
pub const ROBOT_NAME_BYTES: usize = 64;

/// What one side is built for. Published once at start-up (and kept as history).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("chaosd::ArmInfo")]
#[repr(C)]
pub struct ArmInfo {
    /// The [`WIRE_VERSION`] of the publisher's build.
    pub wire_version: u32,
    /// [`KIND_FIXED`] or [`KIND_FLOATING`].
    pub kind: u32,
    /// The publisher's instance id: the plant's `StateSample::plant_id`, or the daemon's
    /// `CommandSample::daemon_id`. Binds a verdict to one process start.
    pub instance_id: u64,
    /// Number of links (joints).
    pub n: u32,
    /// The command interface ([`crate::interface`]) the daemon sends, or the plant takes.
    pub interface: u32,
    /// Link lengths (m); entries `n..` are zero.
    pub links: [f64; MAX_JOINTS],
    /// Floating base only (zero otherwise): link masses (kg) and inertias (kg·m²).
    pub link_masses: [f64; MAX_JOINTS],
    pub link_inertias: [f64; MAX_JOINTS],
    /// Floating base only (zero otherwise): base mass (kg), inertia (kg·m²), offset (m).
    pub base_mass: f64,
    pub base_inertia: f64,
    pub base_offset: f64,
    /// Chain only (zero otherwise): the robot's name and its base and tip links, UTF-8, zero
    /// padded.
    pub robot: [u8; ROBOT_NAME_BYTES],
    /// Chain only: a hash of every number of the chain's model.
    pub fingerprint: u64,
}

/// The floating base's parameters, for [`ArmInfo::new`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FloatingBase<'a> {
    pub link_masses: &'a [f64],
    pub link_inertias: &'a [f64],
    pub base_mass: f64,
    pub base_inertia: f64,
    pub base_offset: f64,
}

fn copy_in(dst: &mut [f64; MAX_JOINTS], src: &[f64]) {
    let n = src.len().min(MAX_JOINTS);
    dst[..n].copy_from_slice(&src[..n]);
}

impl ArmInfo {
    /// The description of an arm with these link lengths; `floating` for a free-floating base.
    /// At most [`MAX_JOINTS`] links are kept (configs are validated long before this).
    pub fn new(instance_id: u64, links: &[f64], floating: Option<FloatingBase<'_>>) -> Self {
        let mut info = Self {
            wire_version: WIRE_VERSION,
            kind: KIND_FIXED,
            instance_id,
            n: links.len().min(MAX_JOINTS) as u32,
            interface: crate::interface::ACCELERATION,
            links: [0.0; MAX_JOINTS],
            link_masses: [0.0; MAX_JOINTS],
            link_inertias: [0.0; MAX_JOINTS],
            base_mass: 0.0,
            base_inertia: 0.0,
            base_offset: 0.0,
            robot: [0; ROBOT_NAME_BYTES],
            fingerprint: 0,
        };
        copy_in(&mut info.links, links);
        if let Some(b) = floating {
            info.kind = KIND_FLOATING;
            copy_in(&mut info.link_masses, b.link_masses);
            copy_in(&mut info.link_inertias, b.link_inertias);
            info.base_mass = b.base_mass;
            info.base_inertia = b.base_inertia;
            info.base_offset = b.base_offset;
        }
        info
    }

    /// The description of a URDF chain of `n` joints named `name` (cut to
    /// [`ROBOT_NAME_BYTES`] at a character boundary), with its model's `fingerprint`.
    ///
    /// ```
    /// let a = protocol::ArmInfo::chain(1, 7, "panda (panda_link0 → panda_link8)", 42);
    /// let b = protocol::ArmInfo::chain(2, 7, "panda (panda_link0 → panda_link7)", 43);
    /// let why = protocol::mismatch("lab", &a, &b).unwrap();
    /// assert!(why.contains("panda_link8") && why.contains("panda_link7"), "{why}");
    /// assert!(protocol::mismatch("lab", &a, &a).is_none());
    /// ```
    pub fn chain(instance_id: u64, n: usize, name: &str, fingerprint: u64) -> Self {
        let mut info = Self::new(instance_id, &[], None);
        info.kind = KIND_CHAIN;
        info.n = n.min(MAX_JOINTS) as u32;
        let mut end = name.len().min(ROBOT_NAME_BYTES);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        info.robot[..end].copy_from_slice(&name.as_bytes()[..end]);
        info.fingerprint = fingerprint;
        info
    }

    /// A chain's name as sent (invalid UTF-8 from a peer shows as a placeholder).
    pub fn robot_name(&self) -> &str {
        let end = self
            .robot
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(ROBOT_NAME_BYTES);
        core::str::from_utf8(&self.robot[..end]).unwrap_or("<not UTF-8>")
    }

    fn used(&self) -> usize {
        (self.n as usize).min(MAX_JOINTS)
    }

    /// Whether two descriptions are of the same arm (the instance ids aside). Floats are
    /// compared exactly: both sides read the numbers from a config, and a length that differs in
    /// the last digit is a different arm.
    pub fn same_arm(&self, other: &Self) -> bool {
        let n = self.used();
        let eq = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        self.wire_version == other.wire_version
            && self.kind == other.kind
            && self.n == other.n
            && (self.kind != KIND_CHAIN
                || (self.robot == other.robot && self.fingerprint == other.fingerprint))
            && eq(&self.links[..n], &other.links[..n])
            && (self.kind != KIND_FLOATING
                || (eq(&self.link_masses[..n], &other.link_masses[..n])
                    && eq(&self.link_inertias[..n], &other.link_inertias[..n])
                    && eq(
                        &[self.base_mass, self.base_inertia, self.base_offset],
                        &[other.base_mass, other.base_inertia, other.base_offset],
                    )))
    }
}

/// Numbers as a config would write them: `1`, `0.5`, `1e-7`.
fn list(values: &[f64]) -> String {
    let mut s = String::new();
    for (i, v) in values.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        let _ = write!(s, "{v}");
    }
    s
}

impl fmt::Display for ArmInfo {
    /// `a 3-link fixed arm (links 1,1,1)`; a floating base adds its masses, inertias and base.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.n as usize;
        if !(MIN_JOINTS..=MAX_JOINTS).contains(&n) {
            return write!(f, "an arm with an invalid link count {}", self.n);
        }
        match self.kind {
            KIND_FIXED => write!(f, "a {n}-link fixed arm (links {})", list(&self.links[..n])),
            KIND_FLOATING => write!(
                f,
                "a {n}-link floating arm (links {}; link masses {}; link inertias {}; base mass {}, inertia {}, offset {})",
                list(&self.links[..n]),
                list(&self.link_masses[..n]),
                list(&self.link_inertias[..n]),
                self.base_mass,
                self.base_inertia,
                self.base_offset
            ),
            KIND_CHAIN => write!(
                f,
                "a {n}-joint {} (model fingerprint {:016x})",
                self.robot_name(),
                self.fingerprint
            ),
            k => write!(f, "an arm of unknown kind {k}"),
        }
    }
}

/// `None` when the plant and the daemon agree; otherwise one line naming both sides, e.g.
/// `plant "lab" is a 4-link fixed arm (links 1,1,1,1), daemon expects a 3-link fixed arm (links
/// 1,1,1); refusing`.
pub fn mismatch(namespace: &str, plant: &ArmInfo, daemon: &ArmInfo) -> Option<String> {
    if plant.same_arm(daemon) && plant.interface == daemon.interface {
        return None;
    }
    if plant.interface != daemon.interface {
        let name = |c| crate::interface::name(c).unwrap_or("unknown");
        return Some(format!(
            "plant {namespace:?} takes {} commands, daemon sends {}; refusing (set [command] mode to the same interface for both)",
            name(plant.interface),
            name(daemon.interface)
        ));
    }
    if plant.wire_version != daemon.wire_version {
        return Some(format!(
            "plant {namespace:?} speaks chaosd wire version {}, daemon wire version {}; refusing (build both from the same chaosd)",
            plant.wire_version, daemon.wire_version
        ));
    }
    Some(format!(
        "plant {namespace:?} is {plant}, daemon expects {daemon}; refusing"
    ))
}

/// The opened `plant/info` or `daemon/info` service.
pub type InfoService<S> = publish_subscribe::PortFactory<S, ArmInfo, ()>;

/// QoS of both info services: the newest description is kept as history for late joiners; one
/// publisher (the plant, or the daemon) per namespace.
pub const INFO_QOS: PubSubQos = PubSubQos {
    history_size: 1,
    subscriber_max_buffer_size: 2,
    subscriber_max_borrowed_samples: 1,
    max_publishers: 1,
    max_subscribers: 8,
    max_nodes: 16,
    safe_overflow: true,
};

/// Opens (or creates) `chaosd/<ns>/plant/info` with [`INFO_QOS`].
pub fn open_plant_info_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<InfoService<S>, ServiceError> {
    open_pubsub(node, names.plant_info(), Channel::PlantInfo, &INFO_QOS)
}

/// Opens (or creates) `chaosd/<ns>/daemon/info` with [`INFO_QOS`].
pub fn open_daemon_info_service<S: iceoryx2::service::Service>(
    node: &Node<S>,
    names: &ServiceNames,
) -> Result<InfoService<S>, ServiceError> {
    open_pubsub(node, names.daemon_info(), Channel::DaemonInfo, &INFO_QOS)
}

/// Which end of the handshake this process is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Daemon,
    Plant,
}

impl Side {
    fn who(self) -> &'static str {
        match self {
            Side::Daemon => "chaosd",
            Side::Plant => "plant",
        }
    }
}

/// Why one side's handshake ports could not be opened: one line for the user.
#[derive(Debug, thiserror::Error)]
pub enum HandshakeError {
    #[error(transparent)]
    Node(#[from] crate::NodeError),
    #[error(transparent)]
    Service(#[from] crate::qos::ServiceError),
    #[error("cannot publish on {service}: {detail} (is another {who} already running in namespace {namespace:?}?)")]
    Publish {
        service: String,
        detail: String,
        who: &'static str,
        namespace: String,
    },
    #[error("cannot publish on {service}: {detail}")]
    Send { service: String, detail: String },
    #[error("cannot subscribe to {service}: {detail}")]
    Subscribe { service: String, detail: String },
}

/// One side's handshake ports: its own description published (and re-offered to peers that
/// join later), the peer's read. The daemon and the plant run the same exchange on a helper
/// thread, each judging the peer's description in its own way.
pub struct Exchange {
    _node: Node<iceoryx2::prelude::ipc::Service>,
    ours: iceoryx2::port::publisher::Publisher<iceoryx2::prelude::ipc::Service, ArmInfo, ()>,
    theirs: iceoryx2::port::subscriber::Subscriber<iceoryx2::prelude::ipc::Service, ArmInfo, ()>,
}

impl Exchange {
    /// Opens both info services in `names`, publishes `mine` on `side`'s and subscribes to the
    /// peer's. The error is one line, for the user.
    pub fn open(side: Side, names: &ServiceNames, mine: ArmInfo) -> Result<Self, HandshakeError> {
        let node_name = match side {
            Side::Daemon => "chaosd-handshake",
            Side::Plant => "chaosd-plant-handshake",
        };
        let node = crate::node(node_name)?;
        let (our_name, their_name) = match side {
            Side::Daemon => (names.daemon_info(), names.plant_info()),
            Side::Plant => (names.plant_info(), names.daemon_info()),
        };
        let (our_svc, their_svc) = match side {
            Side::Daemon => (
                open_daemon_info_service(&node, names),
                open_plant_info_service(&node, names),
            ),
            Side::Plant => (
                open_plant_info_service(&node, names),
                open_daemon_info_service(&node, names),
            ),
        };
        let busy = |e: &dyn core::fmt::Debug| HandshakeError::Publish {
            service: our_name.to_string(),
            detail: format!("{e:?}"),
            who: side.who(),
            namespace: names.namespace().to_string(),
        };
        let ours = our_svc?
            .publisher_builder()
            .create()
            .map_err(|e| busy(&e))?;
        ours.send_copy(mine).map_err(|e| HandshakeError::Send {
            service: our_name.to_string(),
            detail: format!("{e:?}"),
        })?;
        let theirs =
            their_svc?
                .subscriber_builder()
                .create()
                .map_err(|e| HandshakeError::Subscribe {
                    service: their_name.to_string(),
                    detail: format!("{e:?}"),
                })?;
        Ok(Self {
            _node: node,
            ours,
            theirs,
        })
    }

    /// Offers our description to peers that joined since, and returns the newest description
    /// the peer published since the last call, if any.
    pub fn newest_peer(&self) -> Option<ArmInfo> {
        let _ = self.ours.update_connections();
        let mut newest = None;
        while let Ok(Some(s)) = self.theirs.receive() {
            newest = Some(*s);
        }
        newest
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    fn fixed(links: &[f64]) -> ArmInfo {
        ArmInfo::new(1, links, None)
    }

    #[test]
    fn a_different_link_count_is_refused_naming_both_sides() {
        let msg = mismatch("ns", &fixed(&[1.0; 4]), &fixed(&[1.0; 3])).unwrap();
        assert_eq!(
            msg,
            "plant \"ns\" is a 4-link fixed arm (links 1,1,1,1), daemon expects a 3-link fixed arm (links 1,1,1); refusing"
        );
    }

    #[test]
    fn different_lengths_are_refused_and_equal_arms_agree() {
        let msg = mismatch("lab", &fixed(&[1.0, 1.0, 0.5]), &fixed(&[1.0; 3])).unwrap();
        assert!(
            msg.contains("links 1,1,0.5") && msg.contains("links 1,1,1"),
            "{msg}"
        );
        let mut other_start = fixed(&[1.0; 3]);
        other_start.instance_id = 99;
        assert_eq!(mismatch("lab", &other_start, &fixed(&[1.0; 3])), None);
    }

    #[test]
    fn floating_bases_compare_their_base_and_masses() {
        let masses = [1.0; 3];
        let inertias = [0.3, 0.2, 0.1];
        let base = |m| FloatingBase {
            link_masses: &masses,
            link_inertias: &inertias,
            base_mass: m,
            base_inertia: 200.0,
            base_offset: 1.0,
        };
        let a = ArmInfo::new(1, &[1.0; 3], Some(base(200.0)));
        let b = ArmInfo::new(2, &[1.0; 3], Some(base(1.0)));
        assert_eq!(mismatch("x", &a, &a), None);
        let msg = mismatch("x", &b, &a).unwrap();
        assert!(
            msg.contains("floating arm")
                && msg.contains("base mass 1,")
                && msg.contains("base mass 200,"),
            "{msg}"
        );
        assert!(mismatch("x", &fixed(&[1.0; 3]), &a)
            .unwrap()
            .contains("3-link fixed arm"));
    }

    #[test]
    fn a_wire_version_mismatch_names_both_versions() {
        let mut old = fixed(&[1.0; 3]);
        old.wire_version = WIRE_VERSION - 1;
        let msg = mismatch("x", &old, &fixed(&[1.0; 3])).unwrap();
        let both = format!(
            "wire version {}, daemon wire version {WIRE_VERSION}",
            WIRE_VERSION - 1
        );
        assert!(msg.contains(&both), "{msg}");
    }

    #[test]
    fn a_seven_link_arm_is_described_whole() {
        let panda = [0.333, 0.316, 0.0825, 0.384, 0.088, 0.107, 0.1];
        let a = fixed(&panda);
        assert_eq!(a.n, 7);
        assert_eq!(mismatch("x", &a, &a), None);
        let mut last = panda;
        last[6] = 0.2;
        let msg = mismatch("x", &fixed(&last), &a).unwrap();
        assert!(
            msg.contains("7-link fixed arm (links 0.333,0.316,0.0825,0.384,0.088,0.107,0.2)")
                && msg.contains("0.107,0.1);"),
            "{msg}"
        );
    }

    #[test]
    fn a_corrupt_count_is_described_not_indexed() {
        let mut bad = fixed(&[1.0; 3]);
        bad.n = 1000;
        let msg = mismatch("x", &bad, &fixed(&[1.0; 3])).unwrap();
        assert!(msg.contains("invalid link count 1000"), "{msg}");
    }

    /// This layout must not change: it is how two wire versions tell each other apart. It last
    /// changed with the joint capacity (7 → 12, wire version 9; it was 288 bytes).
    #[test]
    fn info_layout_is_frozen() {
        assert_eq!(MAX_JOINTS, 12);
        assert_eq!(size_of::<ArmInfo>(), 408);
        assert_eq!(align_of::<ArmInfo>(), 8);
        assert_eq!(offset_of!(ArmInfo, wire_version), 0);
        assert_eq!(offset_of!(ArmInfo, kind), 4);
        assert_eq!(offset_of!(ArmInfo, instance_id), 8);
        assert_eq!(offset_of!(ArmInfo, n), 16);
        assert_eq!(offset_of!(ArmInfo, links), 24);
        assert_eq!(offset_of!(ArmInfo, link_masses), 120);
        assert_eq!(offset_of!(ArmInfo, link_inertias), 216);
        assert_eq!(offset_of!(ArmInfo, base_mass), 312);
        assert_eq!(offset_of!(ArmInfo, base_inertia), 320);
        assert_eq!(offset_of!(ArmInfo, base_offset), 328);
        assert_eq!(offset_of!(ArmInfo, robot), 336);
        assert_eq!(offset_of!(ArmInfo, fingerprint), 400);
        // SAFETY: type_name only returns the string set by #[type_name].
        assert_eq!(
            unsafe { <ArmInfo as ZeroCopySend>::type_name() },
            "chaosd::ArmInfo"
        );
    }
}
