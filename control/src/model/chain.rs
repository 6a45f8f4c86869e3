//! From a URDF tree to the serial chain the controller drives.
//!
//! The chain is the path of joints from a base link to a tip link. Everything else in the file is
//! either ground (hanging off the base or above it) or load: a link below a chain joint belongs
//! to that joint's body, whether it hangs by a fixed joint or by a movable one held at zero (a
//! gripper's fingers), which is also how pinocchio's reduced model treats it.
//!
//! Each joint's frame is turned once, at load, so that its axis is its local z. The per-tick
//! algorithms then only ever rotate about z (one `sin_cos`, no Rodrigues), whatever axes the
//! maker chose; the turn is folded into the constant placements and inertias.

use super::pose::{z_onto, Pose};
use super::urdf::{self, Description, JointType, Limits};
use super::ModelError;
use crate::basics::MAX_JOINTS;
use crate::basics::MIN_JOINTS;
use nalgebra::{Matrix3, Vector3};
use std::collections::HashMap;

/// How a chain joint moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis, with position limits.
    Revolute,
    /// Rotation about the axis, unbounded.
    Continuous,
    /// Translation along the axis.
    Prismatic,
}

impl JointKind {
    pub fn is_prismatic(self) -> bool {
        self == Self::Prismatic
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Revolute => "revolute",
            Self::Continuous => "continuous",
            Self::Prismatic => "prismatic",
        }
    }
}

/// A rigid body's mass properties: mass, centre of mass and the inertia tensor about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    pub mass: f64,
    pub com: Vector3<f64>,
    pub inertia: Matrix3<f64>,
}

impl Body {
    pub const EMPTY: Body = Body {
        mass: 0.0,
        com: Vector3::new(0.0, 0.0, 0.0),
        inertia: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// The same body seen from a frame in which its old frame sits at `pose`.
    pub fn moved(&self, pose: &Pose) -> Body {
        Body {
            mass: self.mass,
            com: pose.apply(&self.com),
            inertia: pose.rot * self.inertia * pose.rot.transpose(),
        }
    }

    /// Two bodies welded together (parallel-axis theorem about the joint centre of mass).
    pub fn merged(&self, other: &Body) -> Body {
        let mass = self.mass + other.mass;
        if mass <= 0.0 {
            return Body {
                mass: 0.0,
                com: Vector3::zeros(),
                inertia: self.inertia + other.inertia,
            };
        }
        let com = (self.com * self.mass + other.com * other.mass) / mass;
        let shift = |b: &Body| {
            let d = b.com - com;
            b.inertia + (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * b.mass
        };
        Body {
            mass,
            com,
            inertia: shift(self) + shift(other),
        }
    }
}

/// One movable joint of the chain and the body it carries.
#[derive(Debug, Clone, PartialEq)]
pub struct ChainJoint {
    pub name: String,
    pub kind: JointKind,
    /// The axis as the URDF gives it, in the joint's own frame (unit length).
    pub axis: Vector3<f64>,
    pub limits: Limits,
    /// This joint's frame in the previous body's frame (the base's for the first joint), both
    /// turned so that their joint axes are z.
    pub placement: Pose,
    /// Everything this joint moves up to the next chain joint, in the turned joint frame.
    pub body: Body,
    /// The links welded into `body`, the joint's child link first.
    pub links: Vec<String>,
    /// The turn: the child link's URDF frame is `turned frame · turn⁻¹`.
    pub turn: Matrix3<f64>,
}

/// A serial chain loaded from a URDF: the model every algorithm in [`super`] runs on.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    /// The `<robot name>`.
    pub robot: String,
    pub base: String,
    pub tip: String,
    pub joints: Vec<ChainJoint>,
    /// The tip link's frame in the last body's (turned) frame.
    pub tip_placement: Pose,
    /// Gravity in the base frame (default −9.81 m/s² along the base's z).
    pub gravity: Vector3<f64>,
}

/// Earth's gravity along the base's −z.
pub const STANDARD_GRAVITY: Vector3<f64> = Vector3::new(0.0, 0.0, -9.81);

impl Chain {
    /// Loads the chain from `base` to `tip` (defaults: the root link and the only leaf).
    ///
    /// ```
    /// let chain = control::model::Chain::from_urdf(control::model::builtin("panda").unwrap(), None, None).unwrap();
    /// assert_eq!(chain.dof(), 7);
    /// assert_eq!((chain.base.as_str(), chain.tip.as_str()), ("panda_link0", "panda_link8"));
    /// ```
    pub fn from_urdf(
        text: &str,
        base: Option<&str>,
        tip: Option<&str>,
    ) -> Result<Chain, ModelError> {
        let d = urdf::parse(text)?;
        build(&d, base, tip)
    }

    /// Number of movable joints.
    pub fn dof(&self) -> usize {
        self.joints.len()
    }

    /// Total mass the chain moves (every body, loads included; the base is ground).
    pub fn mass(&self) -> f64 {
        self.joints.iter().map(|j| j.body.mass).sum()
    }

    /// An upper bound of the tip's distance from joint 1: the sum of the offsets from each joint
    /// to the next, and from the last to the tip, at full stretch.
    pub fn reach(&self) -> f64 {
        let offsets: f64 = self
            .joints
            .iter()
            .skip(1)
            .map(|j| j.placement.pos.norm())
            .sum();
        offsets + self.tip_placement.pos.norm()
    }
}

/// Who a link's body belongs to while walking down the tree.
#[derive(Clone, Copy)]
struct Owner {
    /// The chain joint whose body the link is welded to (`None`: ground).
    joint: Option<usize>,
    /// The link's frame in that joint's child-link frame (at zero for off-chain joints).
    pose: Pose,
}

fn build(d: &Description, base: Option<&str>, tip: Option<&str>) -> Result<Chain, ModelError> {
    if d.links.is_empty() {
        return Err(ModelError::Empty);
    }
    let tree = Tree::new(d)?;
    let base = match base {
        Some(b) => tree.link(b, "base")?,
        None => tree.root()?,
    };
    let tip = match tip {
        Some(t) => tree.link(t, "tip")?,
        None => tree.only_leaf(base)?,
    };
    let path = tree.path(base, tip)?;
    let chain_joints = movable_on_path(d, &path)?;
    let n = chain_joints.len();
    if !(MIN_JOINTS..=MAX_JOINTS).contains(&n) {
        return Err(ModelError::ChainSize {
            base: d.links[base].name.clone(),
            tip: d.links[tip].name.clone(),
            n,
            joints: names(chain_joints.iter().map(|&j| d.joints[j].name.as_str())),
            min: MIN_JOINTS,
            max: MAX_JOINTS,
        });
    }
    let mut joints = Vec::with_capacity(n);
    let mut acc = Pose::IDENTITY;
    let mut prev_turn = Matrix3::identity();
    for &ji in &path {
        let j = &d.joints[ji];
        let origin = j.origin.clone()?;
        let Some(k) = chain_joints.iter().position(|&c| c == ji) else {
            acc = acc.then(&origin);
            continue;
        };
        let axis = j.axis.clone()?;
        let turn = z_onto(&axis);
        let t = acc.then(&origin);
        let placement = Pose {
            rot: prev_turn.transpose() * t.rot * turn,
            pos: prev_turn.transpose() * t.pos,
        };
        let kind = match j.kind.clone()? {
            JointType::Revolute => JointKind::Revolute,
            JointType::Continuous => JointKind::Continuous,
            _ => JointKind::Prismatic,
        };
        let mut limits = j.limits.clone()?;
        if kind == JointKind::Continuous {
            limits.lower = f64::NEG_INFINITY;
            limits.upper = f64::INFINITY;
        }
        joints.push(ChainJoint {
            name: j.name.clone(),
            kind,
            axis,
            limits,
            placement,
            body: Body::EMPTY,
            links: Vec::new(),
            turn,
        });
        debug_assert_eq!(joints.len(), k + 1);
        acc = Pose::IDENTITY;
        prev_turn = turn;
    }
    let tip_placement = Pose {
        rot: prev_turn.transpose() * acc.rot,
        pos: prev_turn.transpose() * acc.pos,
    };
    weld_bodies(d, &tree, base, &chain_joints, &mut joints)?;
    Ok(Chain {
        robot: d.name.clone(),
        base: d.links[base].name.clone(),
        tip: d.links[tip].name.clone(),
        joints,
        tip_placement,
        gravity: STANDARD_GRAVITY,
    })
}

/// The movable joints on the path, refusing the kinds a chain cannot have.
fn movable_on_path(d: &Description, path: &[usize]) -> Result<Vec<usize>, ModelError> {
    let mut out = Vec::new();
    for &ji in path {
        let j = &d.joints[ji];
        match j.kind.clone()? {
            JointType::Fixed => continue,
            JointType::Floating | JointType::Planar => {
                return Err(ModelError::UnsupportedJoint {
                    joint: j.name.clone(),
                    kind: j.kind.clone()?.name().to_string(),
                })
            }
            JointType::Revolute | JointType::Continuous | JointType::Prismatic => {}
        }
        if let Some(m) = &j.mimic {
            return Err(ModelError::MimicOnChain {
                joint: j.name.clone(),
                mimicked: m.clone(),
            });
        }
        out.push(ji);
    }
    Ok(out)
}

/// Assigns every link below the base to a chain joint's body and sums their inertials.
fn weld_bodies(
    d: &Description,
    tree: &Tree,
    base: usize,
    chain_joints: &[usize],
    joints: &mut [ChainJoint],
) -> Result<(), ModelError> {
    let mut bodies = vec![Body::EMPTY; joints.len()];
    let mut stack = vec![(
        base,
        Owner {
            joint: None,
            pose: Pose::IDENTITY,
        },
    )];
    while let Some((link, owner)) = stack.pop() {
        if let Some(k) = owner.joint {
            joints[k].links.push(d.links[link].name.clone());
            if let Some(inertial) = &d.links[link].inertial {
                let inertial = inertial.clone()?;
                check_inertial(&d.links[link].name, inertial.mass, &inertial.inertia)?;
                let local = Body {
                    mass: inertial.mass,
                    com: Vector3::zeros(),
                    inertia: inertial.inertia,
                };
                let b = local.moved(&owner.pose.then(&inertial.origin));
                bodies[k] = bodies[k].merged(&b);
            }
        }
        for &ji in tree.children(link) {
            let j = &d.joints[ji];
            let next = match chain_joints.iter().position(|&c| c == ji) {
                Some(k) => Owner {
                    joint: Some(k),
                    pose: Pose::IDENTITY,
                },
                None if owner.joint.is_none() => owner,
                None => Owner {
                    joint: owner.joint,
                    pose: owner.pose.then(&j.origin.clone()?),
                },
            };
            stack.push((tree.index[j.child.as_str()], next));
        }
    }
    for (j, b) in joints.iter_mut().zip(bodies) {
        // Into the turned frame: the child link frame is turned by `turn`.
        j.body = b.moved(&Pose {
            rot: j.turn.transpose(),
            pos: Vector3::zeros(),
        });
    }
    Ok(())
}

fn check_inertial(link: &str, mass: f64, inertia: &Matrix3<f64>) -> Result<(), ModelError> {
    if mass < 0.0 {
        return Err(ModelError::NegativeMass {
            link: link.to_string(),
            mass,
        });
    }
    // Zero principal moments are real descriptions' point masses and thin rods (pinocchio takes
    // them too); a negative one beyond rounding is a tensor no body has.
    let eig = inertia.symmetric_eigenvalues();
    let scale = eig.abs().max();
    if eig.min() < -(1e-12 * scale + 1e-18) {
        return Err(ModelError::Inertia {
            link: link.to_string(),
            eigenvalues: format!("{:.3e}, {:.3e}, {:.3e}", eig[0], eig[1], eig[2]),
        });
    }
    Ok(())
}

/// The tree's shape: each link's parent joint and child joints.
struct Tree<'a> {
    d: &'a Description,
    index: HashMap<&'a str, usize>,
    parent: Vec<Option<usize>>,
    children: Vec<Vec<usize>>,
}

impl<'a> Tree<'a> {
    fn new(d: &'a Description) -> Result<Self, ModelError> {
        let mut index = HashMap::new();
        for (i, l) in d.links.iter().enumerate() {
            if index.insert(l.name.as_str(), i).is_some() {
                return Err(ModelError::Duplicate {
                    kind: "link",
                    name: l.name.clone(),
                });
            }
        }
        let mut seen = HashMap::new();
        let mut parent: Vec<Option<usize>> = vec![None; d.links.len()];
        let mut children = vec![Vec::new(); d.links.len()];
        for (ji, j) in d.joints.iter().enumerate() {
            if seen.insert(j.name.as_str(), ji).is_some() {
                return Err(ModelError::Duplicate {
                    kind: "joint",
                    name: j.name.clone(),
                });
            }
            let find = |link: &str, role| {
                index
                    .get(link)
                    .copied()
                    .ok_or_else(|| ModelError::NoSuchLinkInJoint {
                        joint: j.name.clone(),
                        role,
                        link: link.to_string(),
                    })
            };
            let p = find(&j.parent, "parent")?;
            let c = find(&j.child, "child")?;
            if let Some(first) = parent[c] {
                return Err(ModelError::TwoParents {
                    link: j.child.clone(),
                    first: d.joints[first].name.clone(),
                    second: j.name.clone(),
                });
            }
            parent[c] = Some(ji);
            children[p].push(ji);
        }
        let tree = Tree {
            d,
            index,
            parent,
            children,
        };
        tree.check_loops()?;
        Ok(tree)
    }

    /// With one parent per link, a loop is a walk upwards that never reaches a root.
    fn check_loops(&self) -> Result<(), ModelError> {
        for start in 0..self.d.links.len() {
            let mut link = start;
            for _ in 0..=self.d.links.len() {
                match self.parent[link] {
                    None => break,
                    Some(j) => link = self.index[self.d.joints[j].parent.as_str()],
                }
                if link == start {
                    return Err(ModelError::Loop {
                        link: self.d.links[start].name.clone(),
                    });
                }
            }
        }
        Ok(())
    }

    fn children(&self, link: usize) -> &[usize] {
        &self.children[link]
    }

    fn link(&self, name: &str, role: &'static str) -> Result<usize, ModelError> {
        self.index
            .get(name)
            .copied()
            .ok_or_else(|| ModelError::NoSuchLink {
                link: name.to_string(),
                role,
                nearest: nearest(name, self.d.links.iter().map(|l| l.name.as_str())),
                known: names(self.d.links.iter().map(|l| l.name.as_str())),
            })
    }

    /// Movable joints on the way from `base` down to `link` (0 when `link` is not below it).
    fn movable_below(&self, base: usize, link: usize) -> usize {
        self.path(base, link).map_or(0, |joints| {
            joints
                .iter()
                .filter(|&&j| !matches!(self.d.joints[j].kind, Ok(JointType::Fixed)))
                .count()
        })
    }

    fn root(&self) -> Result<usize, ModelError> {
        let roots: Vec<usize> = (0..self.d.links.len())
            .filter(|&l| self.parent[l].is_none())
            .collect();
        match roots.as_slice() {
            [r] => Ok(*r),
            _ => Err(ModelError::Roots {
                count: roots.len(),
                roots: names(roots.iter().map(|&l| self.d.links[l].name.as_str())),
            }),
        }
    }

    fn only_leaf(&self, base: usize) -> Result<usize, ModelError> {
        let mut leaves = Vec::new();
        let mut stack = vec![base];
        while let Some(l) = stack.pop() {
            if self.children[l].is_empty() {
                leaves.push(l);
            }
            for &j in &self.children[l] {
                stack.push(self.index[self.d.joints[j].child.as_str()]);
            }
        }
        match leaves.as_slice() {
            [l] => Ok(*l),
            _ => {
                // The arm's ends first: a user looks for the leaf with the most joints above it.
                let mut ranked: Vec<(usize, usize)> = leaves
                    .iter()
                    .map(|&l| (self.movable_below(base, l), l))
                    .collect();
                ranked.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
                Err(ModelError::AmbiguousTip {
                    count: leaves.len(),
                    leaves: ranked
                        .iter()
                        .map(|&(n, l)| format!("{:?} ({n})", self.d.links[l].name))
                        .collect::<Vec<_>>()
                        .join(", "),
                })
            }
        }
    }

    /// The joints from `base` down to `tip`, in that order.
    fn path(&self, base: usize, tip: usize) -> Result<Vec<usize>, ModelError> {
        let mut out = Vec::new();
        let mut link = tip;
        while link != base {
            let Some(j) = self.parent[link] else {
                return Err(ModelError::NotAncestor {
                    base: self.d.links[base].name.clone(),
                    tip: self.d.links[tip].name.clone(),
                });
            };
            out.push(j);
            link = self.index[self.d.joints[j].parent.as_str()];
        }
        out.reverse();
        Ok(out)
    }
}

/// The names closest to a misspelt `name` (edit distance: at most three, no further than one
/// edit beyond the closest, and within half the name's length), for a message's "did you mean".
fn nearest<'s>(name: &str, it: impl Iterator<Item = &'s str>) -> String {
    let want = name.to_lowercase();
    let mut scored: Vec<(usize, &str)> = it
        .map(|n| (edit_distance(&want, &n.to_lowercase()), n))
        .filter(|&(d, _)| d <= (want.chars().count() / 2).max(2))
        .collect();
    scored.sort();
    let best = scored.first().map_or(0, |&(d, _)| d);
    scored
        .iter()
        .take_while(|&&(d, _)| d <= best + 1)
        .take(3)
        .map(|(_, n)| format!("{n:?}"))
        .collect::<Vec<_>>()
        .join(" or ")
}

/// Levenshtein distance over characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let substitute = diagonal + usize::from(ca != cb);
            diagonal = row[j + 1];
            row[j + 1] = substitute.min(row[j] + 1).min(diagonal + 1);
        }
    }
    row[b.len()]
}

/// A short list of names for a message: at most a dozen, then a count.
fn names<'s>(it: impl Iterator<Item = &'s str>) -> String {
    let all: Vec<&str> = it.collect();
    let mut s = all
        .iter()
        .take(12)
        .map(|n| format!("{n:?}"))
        .collect::<Vec<_>>()
        .join(", ");
    if all.len() > 12 {
        s.push_str(&format!(" and {} more", all.len() - 12));
    }
    s
}
