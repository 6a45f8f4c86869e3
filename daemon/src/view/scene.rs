//! What a viewer draws: the arm's frames and the points it is drawn through, the tool point and
//! its target, the path and the obstacles, in a `world` frame.
//!
//! Built from the running [`System`] off the loop (at a recording's start and after every edit),
//! so the picture always matches what the law is doing. The planar arm gets a generated URDF of
//! its own links (with visuals, so Foxglove's URDF layer has something to show); a URDF chain's
//! description is the file it was loaded from. Joint i's child link is placed relative to joint
//! i−1's, as `robot_state_publisher` does, so the transforms agree with the URDF's tree.

use control::model::Pose;
use control::task::Path;
use control::System;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The root frame every scene entity and the base's transform hang from.
pub const WORLD: &str = "world";

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

/// Kinematics of one arm type, behind a runtime joint count.
trait Geometry: Send {
    fn posed(&self, phi: f64, q: &[f64]) -> Posed;
}

/// The scene of one configuration.
pub struct Scene {
    pub base: String,
    pub joints: Vec<String>,
    pub links: Vec<String>,
    /// The URDF a viewer loads (`/robot_description`), if it could be read.
    pub urdf: Option<String>,
    /// Obstacles as spheres (centre, radius); the planar arm's discs lie in z = 0.
    pub obstacles: Vec<([f64; 3], f64)>,
    /// One period of the path, closed.
    pub path: Vec<[f64; 3]>,
    geometry: Box<dyn Geometry>,
    /// The tool's path (every arm's one type); None for a chain whose set-up does not build.
    task: Option<Path>,
}

/// Points per period in [`Scene::path`].
const PATH_POINTS: usize = 96;

impl Scene {
    /// The scene of a valid `system`.
    pub fn of(system: &System) -> Scene {
        // One period once the path is up to speed: the start-up ramp (`task.ramp`) is not part
        // of the loop the tool goes round.
        let (base, joints, links, urdf, obstacles, geometry) = match system {
            System::Planar(c) => {
                let n = c.n();
                let geometry: Box<dyn Geometry> =
                    control::with_dof!(n, N => Box::new(Planar::<N> { model: c.model::<N>() }));
                let obstacles = c.control.obstacles.iter();
                let obstacles = obstacles.map(|o| ([o.center[0], o.center[1], 0.0], o.radius));
                (
                    "base".to_string(),
                    (1..=n).map(|i| format!("joint{i}")).collect(),
                    (1..=n).map(|i| format!("link{i}")).collect(),
                    Some(planar_urdf(&c.arm.links)),
                    obstacles.collect(),
                    geometry,
                )
            }
            System::Spatial(s) => {
                let chain = &s.chain;
                let geometry: Box<dyn Geometry> = control::with_dof!(chain.dof(), N => match s.config.setup::<N>(chain) {
                    Ok(setup) => Box::new(Spatial::<N> { arm: setup.arm }),
                    Err(_) => Box::new(Nothing(N)),
                });
                let obstacles = s.config.obstacles.iter().map(|o| (o.center, o.radius));
                (
                    chain.base.clone(),
                    chain.joints.iter().map(|j| j.name.clone()).collect(),
                    chain.joints.iter().map(|j| j.links[0].clone()).collect(),
                    rt::robot::text(&s.config.robot.description).ok(),
                    obstacles.collect(),
                    geometry,
                )
            }
        };
        let task = system.path().ok();
        let path = match &task {
            Some(p) => (0..=PATH_POINTS)
                .map(|k| position(p, p.ramp + p.period * k as f64 / PATH_POINTS as f64))
                .collect(),
            None => vec![[0.0; 3]; PATH_POINTS + 1],
        };
        Scene {
            base,
            joints,
            links,
            urdf,
            obstacles,
            path,
            geometry,
            task,
        }
    }

    /// The arm at base angle `phi` (planar floating base; 0 otherwise) and joint positions `q`.
    pub fn posed(&self, phi: f64, q: &[f64]) -> Posed {
        self.geometry.posed(phi, q)
    }

    /// Where the tool should be at controller time `t`.
    pub fn target(&self, t: f64) -> [f64; 3] {
        self.task.as_ref().map_or([0.0; 3], |p| position(p, t))
    }

    /// Each joint's (parent frame, child frame, child in parent): the base in the world, then
    /// every link in the previous one.
    pub fn transforms<'a>(
        &'a self,
        p: &'a Posed,
    ) -> impl Iterator<Item = (&'a str, &'a str, Pose)> {
        let base = std::iter::once((WORLD, self.base.as_str(), p.base));
        let links = p.links.iter().enumerate().map(move |(i, pose)| {
            let (parent, parent_pose) = match i {
                0 => (self.base.as_str(), &p.base),
                _ => (self.links[i - 1].as_str(), &p.links[i - 1]),
            };
            (
                parent,
                self.links[i].as_str(),
                parent_pose.inverse().then(pose),
            )
        });
        base.chain(links)
    }
}

/// A rotation matrix as a unit quaternion `[x, y, z, w]`.
pub fn quaternion(rot: &Matrix3<f64>) -> [f64; 4] {
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*rot));
    [q.i, q.j, q.k, q.w]
}

/// Where a path puts the tool at `t`.
fn position(path: &Path, t: f64) -> [f64; 3] {
    path.position(t).into()
}

struct Planar<const N: usize> {
    model: control::arm::ArmModel<N>,
}

impl<const N: usize> Geometry for Planar<N> {
    fn posed(&self, phi: f64, q: &[f64]) -> Posed {
        let qv = control::VecN::<N>::from_fn(|i, _| q.get(i).copied().unwrap_or(0.0));
        let mut kin = control::arm::Kinematics::<N>::default();
        self.model
            .kinematics(phi, &qv, &control::VecN::<N>::zeros(), &mut kin);
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
    arm: control::arm::spatial::SpatialArm<N>,
}

impl<const N: usize> Geometry for Spatial<N> {
    fn posed(&self, _phi: f64, q: &[f64]) -> Posed {
        let qv = control::VecN::<N>::from_fn(|i, _| q.get(i).copied().unwrap_or(0.0));
        let mut kin = control::arm::spatial::SpatialKinematics::<N>::default();
        self.arm
            .kinematics(&qv, &control::VecN::<N>::zeros(), &mut kin);
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

/// A chain whose set-up does not build (never for a validated system): drawn folded at the base.
struct Nothing(usize);

impl Geometry for Nothing {
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
pub fn planar_urdf(links: &[f64]) -> String {
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
    use super::*;

    #[test]
    fn the_planar_scene_puts_the_tip_at_the_sum_of_the_links_and_agrees_with_its_urdf() {
        let sys = rt::robot::preset("paper").unwrap();
        let scene = Scene::of(&sys);
        let p = scene.posed(0.0, &[0.0, 0.0, 0.0]);
        assert!((p.tip[0] - 3.0).abs() < 1e-12 && p.tip[1].abs() < 1e-12);
        let q = [0.3, -0.7, 1.1];
        let p = scene.posed(0.0, &q);
        // The generated URDF, loaded by chaosd's own URDF reader, puts the tip where the scene
        // does.
        let urdf = scene.urdf.as_deref().unwrap();
        let chain = control::model::Chain::from_urdf(urdf, None, None).unwrap();
        let model = chain.model::<3>().unwrap();
        let mut f = control::model::Frames::<3>::default();
        model.frames(&control::VecN::<3>::from_column_slice(&q), &mut f);
        let last = f.link(&model, 2).then(&Pose {
            rot: Matrix3::identity(),
            pos: Vector3::new(1.0, 0.0, 0.0),
        });
        assert!((last.pos - Vector3::from(p.tip)).norm() < 1e-12);
        // Chaining the relative transforms gives back every link's world pose.
        let mut world = Pose::IDENTITY;
        for (k, (_, child, rel)) in scene.transforms(&p).enumerate() {
            world = world.then(&rel);
            if k > 0 {
                assert_eq!(child, format!("link{k}"));
                assert!((world.pos - p.links[k - 1].pos).norm() < 1e-12);
                assert!((world.rot - p.links[k - 1].rot).norm() < 1e-12);
            }
        }
    }

    #[test]
    fn the_panda_scene_has_its_urdf_link_names_and_a_closed_path() {
        let sys = rt::robot::preset("panda").unwrap();
        let scene = Scene::of(&sys);
        assert_eq!(scene.links.len(), 7);
        assert_eq!(scene.links[0], "panda_link1");
        assert!(scene.urdf.as_deref().unwrap().contains("panda_link7"));
        let (a, b) = (scene.path[0], scene.path[scene.path.len() - 1]);
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-9), "{a:?} {b:?}");
        let p = scene.posed(0.0, &[0.0; 7]);
        assert_eq!(p.points.len(), 8);
        assert_eq!(quaternion(&Matrix3::identity()), [0.0, 0.0, 0.0, 1.0]);
    }
}
