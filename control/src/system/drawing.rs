//! The arm as a viewer draws it (Foxglove live, MCAP recordings): the names of its frames, each
//! link's frame at a state, the polyline through its joints and the tool point. Built once per
//! set-up ([`System::drawing`]) and then posed at every drawn state, so a viewer that draws at
//! the telemetry rate never rebuilds the arm. Joint i's child link is placed as the URDF's
//! tree places it (`robot_state_publisher`'s convention), so the frames agree with the URDF a
//! viewer loads: a robot's own description, or for the paper's planar arm the one
//! [`Drawing::generated_urdf`] writes.

use super::System;
use crate::arm::spatial::{SpatialArm, SpatialKinematics};
use crate::arm::{ArmModel, Kinematics, VecN};
use crate::model::Pose;
use nalgebra::{Rotation3, Vector3};

/// The arm at one state.
#[derive(Clone, Debug, Default)]
pub struct Posed {
    /// The base link's frame in the world (moves only with a floating base).
    pub base: Pose,
    /// Each joint's child link frame (the URDF frame) in the world.
    pub links: Vec<Pose>,
    /// The polyline the arm is drawn as: the base, each joint's origin after the first, the
    /// tool point.
    pub points: Vec<[f64; 3]>,
    /// The tool point.
    pub tip: [f64; 3],
}

/// An arm's frames, built once: see the module's text.
pub struct Drawing {
    /// The base link's name, each joint's and each joint's child link's.
    pub base: String,
    pub joints: Vec<String>,
    pub links: Vec<String>,
    /// The URDF of an arm that has no description file (the paper's planar arm: revolute
    /// joints about z, each link a thin box of its length); `None` for a robot, whose
    /// description the caller reads (this crate does no I/O).
    pub generated_urdf: Option<String>,
    geometry: Box<dyn Geometry>,
}

/// Kinematics of one arm type, behind a runtime joint count.
trait Geometry: Send {
    fn posed(&self, phi: f64, q: &[f64]) -> Posed;
}

impl Drawing {
    /// The arm at base angle `phi` (planar floating base; 0 otherwise) and joint positions `q`
    /// (missing joints at 0).
    ///
    /// ```
    /// let s = control::System::preset("panda", &control::system::builtin_robot).unwrap();
    /// let d = s.drawing();
    /// assert_eq!((d.links.len(), d.links[0].as_str()), (7, "panda_link1"));
    /// assert_eq!(d.posed(0.0, &[0.0; 7]).points.len(), 8);
    /// ```
    pub fn posed(&self, phi: f64, q: &[f64]) -> Posed {
        self.geometry.posed(phi, q)
    }
}

impl System {
    /// The arm's [`Drawing`]. A robot whose set-up does not build (never a validated one) is
    /// drawn folded at its base.
    pub fn drawing(&self) -> Drawing {
        match self {
            System::Planar(c) => {
                let n = c.n();
                Drawing {
                    base: "base".into(),
                    joints: (1..=n).map(|i| format!("joint{i}")).collect(),
                    links: (1..=n).map(|i| format!("link{i}")).collect(),
                    generated_urdf: Some(planar_urdf(&c.arm.links)),
                    geometry: crate::with_dof!(n, N => Box::new(Planar::<N> { model: c.model::<N>() })),
                }
            }
            System::Spatial(s) => {
                let chain = &s.chain;
                let geometry: Box<dyn Geometry> = crate::with_dof!(chain.dof(), N => {
                    match s.config.setup::<N>(chain) {
                        Ok(setup) => Box::new(Spatial::<N> { arm: setup.arm }),
                        Err(_) => Box::new(Folded(N)),
                    }
                });
                Drawing {
                    base: chain.base.clone(),
                    joints: chain.joints.iter().map(|j| j.name.clone()).collect(),
                    links: chain.joints.iter().map(|j| j.links[0].clone()).collect(),
                    generated_urdf: None,
                    geometry,
                }
            }
        }
    }
}

/// Joint positions as a fixed-size vector, missing ones at 0.
fn joints<const N: usize>(q: &[f64]) -> VecN<N> {
    VecN::<N>::from_fn(|i, _| q.get(i).copied().unwrap_or(0.0))
}

struct Planar<const N: usize> {
    model: ArmModel<N>,
}

impl<const N: usize> Geometry for Planar<N> {
    fn posed(&self, phi: f64, q: &[f64]) -> Posed {
        let qv = joints::<N>(q);
        let mut kin = Kinematics::<N>::default();
        self.model
            .kinematics(phi, &qv, &VecN::<N>::zeros(), &mut kin);
        let at = |x: f64, y: f64, angle: f64| Pose {
            rot: *Rotation3::from_axis_angle(&Vector3::z_axis(), angle).matrix(),
            pos: Vector3::new(x, y, 0.0),
        };
        let p0 = kin.points[0];
        let mut angle = phi;
        let links = (0..N)
            .map(|i| {
                angle += qv[i];
                at(kin.points[i].x, kin.points[i].y, angle)
            })
            .collect();
        let mut points: Vec<[f64; 3]> = kin.points.iter().map(|p| [p.x, p.y, 0.0]).collect();
        points.push([kin.p.x, kin.p.y, 0.0]);
        Posed {
            base: at(p0.x, p0.y, phi),
            links,
            points,
            tip: [kin.p.x, kin.p.y, 0.0],
        }
    }
}

struct Spatial<const N: usize> {
    arm: SpatialArm<N>,
}

impl<const N: usize> Geometry for Spatial<N> {
    fn posed(&self, _phi: f64, q: &[f64]) -> Posed {
        let qv = joints::<N>(q);
        let mut kin = SpatialKinematics::<N>::default();
        self.arm.kinematics(&qv, &VecN::<N>::zeros(), &mut kin);
        let f = &kin.frames;
        let mut points = vec![[0.0; 3]];
        points.extend(f.body.iter().skip(1).map(|b| [b.pos.x, b.pos.y, b.pos.z]));
        points.push([kin.p.x, kin.p.y, kin.p.z]);
        Posed {
            base: Pose::IDENTITY,
            links: (0..N).map(|i| f.link(&self.arm.model, i)).collect(),
            points,
            tip: [kin.p.x, kin.p.y, kin.p.z],
        }
    }
}

/// A chain whose set-up does not build: every link at the base.
struct Folded(usize);

impl Geometry for Folded {
    fn posed(&self, _phi: f64, _q: &[f64]) -> Posed {
        Posed {
            base: Pose::IDENTITY,
            links: vec![Pose::IDENTITY; self.0],
            points: vec![[0.0; 3]],
            tip: [0.0; 3],
        }
    }
}

/// The planar arm as a URDF: revolute joints about z, link j a thin box of its length.
fn planar_urdf(links: &[f64]) -> String {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<robot name=\"chaosd_planar\">\n  <link name=\"base\"/>\n",
    );
    for (i, l) in links.iter().enumerate() {
        let j = i + 1;
        let (parent, x) = match i {
            0 => ("base".to_string(), 0.0),
            _ => (format!("link{i}"), links[i - 1]),
        };
        s += &format!(
            "  <joint name=\"joint{j}\" type=\"continuous\">\n    <parent link=\"{parent}\"/>\n    <child link=\"link{j}\"/>\n    <origin xyz=\"{x} 0 0\" rpy=\"0 0 0\"/>\n    <axis xyz=\"0 0 1\"/>\n  </joint>\n  <link name=\"link{j}\">\n    <visual>\n      <origin xyz=\"{} 0 0\" rpy=\"0 0 0\"/>\n      <geometry><box size=\"{l} 0.04 0.04\"/></geometry>\n    </visual>\n  </link>\n",
            l / 2.0
        );
    }
    s + "</robot>\n"
}
