//! Why a robot description could not become a model.
//!
//! Every variant names the element at fault (link, joint, attribute) so that a user holding a
//! maker's URDF can go straight to the line to fix; none of them is ever a panic.

/// A URDF that chaosd cannot turn into a chain, naming the element at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    #[error("robot description is {bytes} bytes; the limit is {limit} bytes")]
    TooLarge { bytes: usize, limit: usize },
    #[error("not XML: {message}")]
    NotXml { message: String },
    #[error("root element is <{found}>; a URDF's root is <robot>")]
    NotUrdf { found: String },
    #[error("{element} has no {attribute:?} attribute")]
    Missing { element: String, attribute: String },
    #[error("{element}: {attribute} = {value:?} is not {expected}")]
    BadNumber {
        element: String,
        attribute: String,
        value: String,
        expected: &'static str,
    },
    #[error("two {kind}s are named {name:?}")]
    Duplicate { kind: &'static str, name: String },
    #[error("joint {joint:?} names {role} link {link:?}, which the file does not define")]
    NoSuchLinkInJoint {
        joint: String,
        role: &'static str,
        link: String,
    },
    #[error(
        "no link named {link:?} (the {role}){}; links: {known}",
        did_you_mean(nearest)
    )]
    NoSuchLink {
        link: String,
        role: &'static str,
        /// The closest names, `"a" or "b"`; empty when none is close.
        nearest: String,
        known: String,
    },
    #[error("link {link:?} has two parent joints, {first:?} and {second:?}; a URDF is a tree")]
    TwoParents {
        link: String,
        first: String,
        second: String,
    },
    #[error("the joints form a loop through link {link:?}; a URDF is a tree")]
    Loop { link: String },
    #[error("the description has {count} root links ({roots}); a URDF has one")]
    Roots { count: usize, roots: String },
    #[error("the description has no links")]
    Empty,
    #[error("{count} leaf links: name the tip link (--tip or robot.tip); each with the movable joints above it: {leaves}")]
    AmbiguousTip { count: usize, leaves: String },
    #[error("link {base:?} is not on the path from the root to {tip:?}: the base must be an ancestor of the tip")]
    NotAncestor { base: String, tip: String },
    #[error("joint {joint:?} on the chain is {kind:?}; chains may have revolute, continuous, prismatic and fixed joints")]
    UnsupportedJoint { joint: String, kind: String },
    #[error("joint {joint:?} on the chain mimics {mimicked:?}; mimic joints are only supported off the chain")]
    MimicOnChain { joint: String, mimicked: String },
    #[error("joint {joint:?} has type {kind:?}; URDF types are revolute, continuous, prismatic, fixed, floating, planar")]
    UnknownJointType { joint: String, kind: String },
    #[error("joint {joint:?} has a zero axis")]
    ZeroAxis { joint: String },
    #[error("the chain from {base:?} to {tip:?} has {n} movable joints ({joints}); chaosd handles {min} to {max}")]
    ChainSize {
        base: String,
        tip: String,
        n: usize,
        joints: String,
        min: usize,
        max: usize,
    },
    #[error("link {link:?} has mass {mass}; a mass must be zero or positive")]
    NegativeMass { link: String, mass: f64 },
    #[error(
        "link {link:?}: the inertia tensor has a negative principal moment (eigenvalues {eigenvalues}): no body has that inertia"
    )]
    Inertia { link: String, eigenvalues: String },
    #[error("joint {joint:?}: limit lower = {lower} is above upper = {upper}")]
    LimitOrder {
        joint: String,
        lower: f64,
        upper: f64,
    },
    #[error("joint {joint:?}: limit {attribute} = {value} must not be negative")]
    NegativeLimit {
        joint: String,
        attribute: &'static str,
        value: f64,
    },
    #[error(
        "no built-in robot named {name:?} (built-in: {known}); give a path to a .urdf file instead"
    )]
    UnknownRobot { name: String, known: String },
    #[error("robot size mismatch: the chain has {chain} joints, the caller asked for {asked}")]
    Dof { chain: usize, asked: usize },
}

/// Why the robot a set-up names could not be had: its description unreadable, too large, or
/// not a chain. The loader that reads files (`rt::robot`) reports with it; this crate, which
/// does no I/O, only names the failure, so that [`crate::system::System`] can say which field
/// was at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotError {
    #[error("cannot read robot description {path}: {reason}")]
    Read {
        path: std::path::PathBuf,
        /// The operating system's words.
        reason: String,
    },
    #[error("robot description {path} is over {limit} bytes")]
    TooLarge {
        path: std::path::PathBuf,
        limit: usize,
    },
    #[error("{origin}: {error}")]
    Model { origin: String, error: ModelError },
}

/// `, did you mean "a"?`, or nothing when no name is close.
fn did_you_mean(nearest: &str) -> String {
    if nearest.is_empty() {
        String::new()
    } else {
        format!("; did you mean {nearest}?")
    }
}
