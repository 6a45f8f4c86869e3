//! The arm as a viewer draws it (Foxglove live, MCAP recordings): the names of its frames, each
//! link's frame at a state, the polyline through its joints and the tool point. Built once per
//! set-up ([`System::drawing`]) and then posed at every drawn state, so a viewer that draws at
//! the telemetry rate never rebuilds the arm. Joint i's child link is placed as the URDF's
//! tree places it (`robot_state_publisher`'s convention), so the frames agree with the URDF a
//! viewer loads: a robot's own description, or for the paper's planar arm the one
//! [`Drawing::generated_urdf`] writes. Figures draw the same polyline, and the path the tool
//! goes round ([`System::path`]).

use super::System;
use crate::arm::spatial::{SpatialArm, SpatialKinematics};
use crate::arm::{ArmModel, Kinematics, VecN};
use crate::model::Pose;
use crate::task::Vec3;
use nalgebra::{Rotation3, Vector3};

/// The arm at one state.
#[derive(Clone, Debug, Default)]
pub struct Posed {
    /// The base link's frame in the world (moves only with a floating base).
    pub base: Pose,
    /// Each joint's child link frame (the URDF frame) in the world.
    pub links: Vec<Pose>,
    /// The polyline the arm is drawn as, in figures and viewers alike: the base, each joint's
    /// origin, the tool point (about these, a robot's capsules unless `robot.capsules` gives
    /// them ends of their own).
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
    /// assert_eq!(d.posed(0.0, &[0.0; 7]).points.len(), 9); // the base, 7 joints, the tool
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
                    generated_urdf: Some(planar_urdf(&c.planar_part().arm.links)),
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

    /// The path the tool goes round (a robot's centred where its file or its start puts it).
    ///
    /// ```
    /// let s = control::System::preset("panda", &control::system::builtin_robot).unwrap();
    /// let path = s.path().unwrap();
    /// assert!(path.period > 0.0);
    /// ```
    pub fn path(&self) -> Result<crate::task::Path, crate::basics::ConfigError> {
        match self {
            System::Planar(c) => Ok(c.law_params().task),
            System::Spatial(s) => crate::with_dof!(s.chain.dof(), N => {
                Ok(s.config.setup::<N>(&s.chain)?.params.task.path)
            }),
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
        // The base, each joint's origin, then the tool point.
        let points = std::iter::once(Vec3::zeros())
            .chain((0..N).map(|j| kin.origin(j)))
            .chain(std::iter::once(kin.p))
            .map(|p| [p.x, p.y, p.z])
            .collect();
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

#[cfg(test)]
mod tests {
    use crate::system::builtin_robot;
    use crate::System;

    /// A robot's path is centred so that it starts where the tool is at q(0): the polyline
    /// (base, 7 joint origins, tool) ends where the path begins.
    #[test]
    fn the_pandas_tool_at_the_start_is_where_its_path_begins() {
        let s = System::preset("panda", &builtin_robot).unwrap();
        let q0 = s.initial_state::<7>().q;
        let pts = s.drawing().posed(0.0, q0.as_slice()).points;
        assert_eq!(pts.len(), 9);
        assert_eq!(pts[0], [0.0; 3], "the base");
        let start = s.path().unwrap().position(0.0);
        let off = (crate::task::Vec3::from(pts[8]) - start).norm();
        assert!(off < 1e-12, "the tool is {off} m from the path's start");
    }
}
