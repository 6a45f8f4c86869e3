//! The arm as a picture needs it, whichever arm it is: its links as a polyline and the path its
//! tool goes round. Offline (figures, viewers), never on the loop: each call builds the arm.

use super::System;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::{Kinematics, VecN};
use crate::basics::ConfigError;
use crate::task::{Path, Vec3};

impl System {
    /// The arm at base attitude `phi` (the planar floating base's; ignored by every other arm)
    /// and posture `q` as a polyline in the base frame: the base, each joint's origin, the
    /// tool point (the planar arm's lie in z = 0).
    ///
    /// ```
    /// let s = control::System::preset("paper", &control::system::builtin_robot).unwrap();
    /// let pts = s.links_at(0.0, &[0.0, 0.0, 0.0]).unwrap();
    /// assert_eq!(pts.len(), 4);
    /// assert!((pts[3].x - 3.0).abs() < 1e-12); // three unit links, stretched along x
    /// ```
    pub fn links_at(&self, phi: f64, q: &[f64]) -> Result<Vec<Vec3>, ConfigError> {
        crate::with_dof!(self.n(), N => {
            let qv = VecN::<N>::from_fn(|i, _| q.get(i).copied().unwrap_or(0.0));
            match self {
                System::Planar(c) => {
                    let mut kin = Kinematics::<N>::default();
                    c.model::<N>().kinematics(phi, &qv, &VecN::<N>::zeros(), &mut kin);
                    let points = kin.points.iter().chain(std::iter::once(&kin.p));
                    Ok(points.map(|p| Vec3::new(p.x, p.y, 0.0)).collect())
                }
                System::Spatial(s) => {
                    let arm = s.config.setup::<N>(&s.chain)?.arm;
                    let mut kin = SpatialKinematics::<N>::default();
                    arm.kinematics(&qv, &VecN::<N>::zeros(), &mut kin);
                    let joints = arm.capsule_positions(&kin);
                    Ok(std::iter::once(Vec3::zeros()).chain(joints[..=N].iter().copied()).collect())
                }
            }
        })
    }

    /// The path the tool goes round (a robot's centred where its file or its start puts it).
    ///
    /// ```
    /// let s = control::System::preset("panda", &control::system::builtin_robot).unwrap();
    /// let path = s.path().unwrap();
    /// assert!(path.period > 0.0);
    /// ```
    pub fn path(&self) -> Result<Path, ConfigError> {
        match self {
            System::Planar(c) => Ok(c.law_params().task),
            System::Spatial(s) => crate::with_dof!(s.chain.dof(), N => {
                Ok(s.config.setup::<N>(&s.chain)?.params.task.path)
            }),
        }
    }
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
        let pts = s.links_at(0.0, q0.as_slice()).unwrap();
        assert_eq!(pts.len(), 9);
        assert_eq!(pts[0], crate::task::Vec3::zeros(), "the base");
        let start = s.path().unwrap().position(0.0);
        let off = (pts[8] - start).norm();
        assert!(off < 1e-12, "the tool is {off} m from the path's start");
    }
}
