//! What a viewer draws: the arm's frames and the points it is drawn through, the tool point and
//! its target, the path and the obstacles, in a `world` frame.
//!
//! Built from the running [`System`] off the loop (at a recording's start and after every edit),
//! so the picture always matches what the law is doing. The arm itself is the set-up's
//! [`Drawing`] (its frames' names, posed at each drawn state); the URDF a viewer loads is a
//! robot's description file, read here, or the one the drawing generates for the planar arm.

use control::model::Pose;
pub use control::system::{Drawing, Posed};
use control::task::Path;
use control::System;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

/// The root frame every scene entity and the base's transform hang from.
pub const WORLD: &str = "world";

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
    drawing: Drawing,
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
        let drawing = system.drawing();
        let urdf = drawing.generated_urdf.clone().or_else(|| {
            let r = system.robot()?;
            rt::robot::text(&r.own().robot.description).ok()
        });
        let obstacles = system.obstacle_rows().into_iter().map(|o| {
            let z = o.center.get(2).copied().unwrap_or(0.0);
            ([o.center[0], o.center[1], z], o.radius)
        });
        let task = system.path().ok();
        let path = match &task {
            Some(p) => (0..=PATH_POINTS)
                .map(|k| position(p, p.ramp + p.period * k as f64 / PATH_POINTS as f64))
                .collect(),
            None => vec![[0.0; 3]; PATH_POINTS + 1],
        };
        Scene {
            base: drawing.base.clone(),
            joints: drawing.joints.clone(),
            links: drawing.links.clone(),
            urdf,
            obstacles: obstacles.collect(),
            path,
            drawing,
            task,
        }
    }

    /// The arm at base angle `phi` (planar floating base; 0 otherwise) and joint positions `q`.
    pub fn posed(&self, phi: f64, q: &[f64]) -> Posed {
        self.drawing.posed(phi, q)
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

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
        assert_eq!(p.points.len(), 9);
        assert_eq!(quaternion(&Matrix3::identity()), [0.0, 0.0, 0.0, 1.0]);
    }
}
