//! How a robot description reaches a process: a built-in name or a URDF file.
//!
//! The math crate parses text and does no I/O; this is the one place that turns what a user
//! typed (`panda`, `./my_arm.urdf`) into that text, with a size limit so that a wrong path to a
//! huge file fails at once instead of filling memory. It lives here, beside the other shared
//! plumbing, because the daemon, the plant and the client must read a config the same way and
//! the daemon may not depend on the plant.

pub use control::model::RobotError;
use control::model::{builtin, Chain, MAX_URDF_BYTES};
use control::{ConfigError, System};
use std::io::Read;
use std::path::Path;

/// Loads the chain from `base` to `tip` of a built-in robot (by name) or of a URDF file.
///
/// ```
/// let chain = rt::robot::load("panda", None, None).unwrap();
/// assert_eq!(chain.dof(), 7);
/// let e = rt::robot::load("ur99", None, None).unwrap_err().to_string();
/// assert!(e.contains("panda, planar3"), "{e}");
/// ```
pub fn load(spec: &str, base: Option<&str>, tip: Option<&str>) -> Result<Chain, RobotError> {
    let (origin, text) = match builtin(spec) {
        Ok(text) => (format!("built-in robot {spec:?}"), text.to_string()),
        Err(unknown) if looks_like_a_name(spec) => {
            return Err(RobotError::Model {
                origin: format!("robot {spec:?}"),
                error: unknown,
            })
        }
        Err(_) => (spec.to_string(), read(Path::new(spec))?),
    };
    Chain::from_urdf(&text, base, tip).map_err(|error| RobotError::Model { origin, error })
}

/// The URDF text of a built-in robot (by name) or of a file, as [`load`] reads it: for a
/// recording's `/robot_description`, so a viewer draws the same robot.
///
/// ```
/// assert!(rt::robot::text("panda").unwrap().contains("panda_link0"));
/// ```
pub fn text(spec: &str) -> Result<String, RobotError> {
    match builtin(spec) {
        Ok(text) => Ok(text.to_string()),
        Err(error) if looks_like_a_name(spec) => Err(RobotError::Model {
            origin: format!("robot {spec:?}"),
            error,
        }),
        Err(_) => read(Path::new(spec)),
    }
}

/// A bare word that is not a file here: the user meant a built-in robot.
fn looks_like_a_name(spec: &str) -> bool {
    !spec.contains('/') && !spec.ends_with(".urdf") && !Path::new(spec).exists()
}

fn read(path: &Path) -> Result<String, RobotError> {
    let err = |error: std::io::Error| RobotError::Read {
        path: path.to_path_buf(),
        reason: error.to_string(),
    };
    let file = std::fs::File::open(path).map_err(err)?;
    let mut text = String::new();
    file.take(MAX_URDF_BYTES as u64 + 1)
        .read_to_string(&mut text)
        .map_err(err)?;
    if text.len() > MAX_URDF_BYTES {
        return Err(RobotError::TooLarge {
            path: path.to_path_buf(),
            limit: MAX_URDF_BYTES,
        });
    }
    Ok(text)
}

/// Loads a config file's text (or a preset) as a [`System`]: a `[robot]` table's chain is read
/// with [`load`].
///
/// ```
/// let s = rt::robot::preset("panda").unwrap();
/// assert_eq!(s.n(), 7);
/// assert_eq!(rt::robot::preset("demo").unwrap().n(), 3);
/// ```
pub fn preset(name: &str) -> Result<System, ConfigError> {
    System::preset(name, &resolve)
}

/// Parses a config file's text as a [`System`] (see [`preset`]).
pub fn parse(text: &str) -> Result<System, ConfigError> {
    System::parse(text, &resolve)
}

/// [`load`] as `System` wants it.
pub fn resolve(spec: &str, base: Option<&str>, tip: Option<&str>) -> Result<Chain, RobotError> {
    load(spec, base, tip)
}

/// The arm `system` describes, as the handshake sends it, for the process with `instance_id`
/// (0 for a plant, whose id the loop fills in): the planar arm's links (and a floating base's
/// masses), or a chain's name and fingerprint, and the command interface it uses. The daemon
/// and the plant describe themselves with this one function, so they agree whenever their
/// set-ups do.
pub fn arm_info(system: &System, instance_id: u64) -> protocol::ArmInfo {
    let mut info = match system {
        System::Spatial(s) => {
            let id = s.identity();
            protocol::ArmInfo::chain(instance_id, s.chain.dof(), &id.name, id.fingerprint)
        }
        System::Planar(c) => {
            let arm = &c.planar_part().arm;
            let masses = c.link_masses();
            let inertias = c.link_inertias();
            let floating = (arm.model == control::config::ModelKind::Floating).then(|| {
                protocol::FloatingBase {
                    link_masses: &masses,
                    link_inertias: &inertias,
                    base_mass: arm.base_mass,
                    base_inertia: arm.base_inertia,
                    base_offset: arm.base_offset,
                }
            });
            protocol::ArmInfo::new(instance_id, &arm.links, floating)
        }
    };
    info.interface = system.command_mode().code();
    info
}
