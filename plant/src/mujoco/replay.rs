//! MuJoCo as the judge of a motion it did not make: a trajectory of chaosd's joints (a study's
//! run) posed in MuJoCo's model sample after sample, its collision detection and geom distances
//! over the model's own geometry (a robot's meshes) counting contact, as [`super::judge`] does
//! for a live run. The study moves the arm by chaosd's simulation and its filter keeps chaosd's
//! capsules clear; this says whether the meshes were clear too.
//!
//! ```no_run
//! use plant::mujoco::replay::Replay;
//! use std::collections::BTreeMap;
//! let joints: Vec<String> = (1..=7).map(|i| format!("panda_joint{i}")).collect();
//! let q0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
//! let spheres = [([0.4, 0.0, 0.5], 0.05)];
//! let model = std::path::Path::new("out/mujoco/panda.urdf");
//! let mut r = Replay::new(model, &BTreeMap::new(), &joints, &spheres, &q0).unwrap();
//! r.pose(0.0, &q0);
//! println!("{:?}", r.report());
//! ```

use super::judge::Judge;
use super::load::{self, Source};
use crate::report::ContactReport;
use anyhow::{bail, Result};
use mujoco_rs::mujoco_c::{mjModel, mj_fwdPosition};
use mujoco_rs::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub struct Replay {
    data: MjData<Box<MjModel>>,
    /// `qpos` addresses of chaosd's joints, in chaosd's order.
    arm: Vec<usize>,
    judge: Judge,
}

impl Replay {
    /// `model` (URDF or MJCF) with `spheres` (centre, radius; m) as obstacles; `joints` are
    /// chaosd's, found by name; body pairs touching at `q0` are excluded, as in a live run.
    pub fn new(
        model: &Path,
        packages: &BTreeMap<String, PathBuf>,
        joints: &[String],
        spheres: &[([f64; 3], f64)],
        q0: &[f64],
    ) -> Result<Self> {
        if spheres.len() > super::scene::MAX {
            bail!(
                "{} obstacles: MuJoCo's scene holds at most {}",
                spheres.len(),
                super::scene::MAX
            );
        }
        if q0.len() != joints.len() {
            bail!("{} joint angles for {} joints", q0.len(), joints.len());
        }
        // The step does not matter: nothing is integrated.
        let built = load::build(Source::File(model), packages, (spheres, q0), joints, 1e-3)?;
        let excluded = built.excluded.len();
        let data = MjData::new(built.model);
        let mut judge = Judge::new(data.model().ffi(), built.obstacles, excluded);
        judge.set_active(spheres.len());
        Ok(Self {
            arm: built.arm.iter().map(|a| a.0).collect(),
            data,
            judge,
        })
    }

    /// Poses the arm at `q` (chaosd's joints) at time `t` and judges it.
    pub fn pose(&mut self, t: f64, q: &[f64]) {
        let m: *const mjModel = self.data.model().ffi();
        // SAFETY: the data owns the model, which outlives both references; the addresses come
        // from the model's joint table.
        let (m, d) = unsafe { (&*m, self.data.ffi_mut()) };
        for (&a, &v) in self.arm.iter().zip(q) {
            unsafe { *d.qpos.add(a) = v };
        }
        // SAFETY: a live model and its data.
        unsafe { mj_fwdPosition(m, d) };
        self.judge.observe(m, d, t);
    }

    pub fn report(&self) -> ContactReport {
        self.judge.report(self.data.model().ffi())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A two-link arm with capsule links along z: a sphere on the first link's side is touched
    /// when the arm stands in it, and not when it stands clear.
    const ARM: &str = r#"<mujoco model="two">
  <worldbody>
    <body name="l1" pos="0 0 0">
      <joint name="j1" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 0.5" size="0.04"/>
      <body name="l2" pos="0 0 0.5">
        <joint name="j2" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.5" size="0.04"/>
      </body>
    </body>
  </worldbody>
</mujoco>"#;

    fn replay(spheres: &[([f64; 3], f64)]) -> Replay {
        let dir = std::env::temp_dir().join(format!("chaosd-replay-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("two.xml");
        std::fs::write(&path, ARM).unwrap();
        let joints = ["j1".to_string(), "j2".to_string()];
        Replay::new(&path, &BTreeMap::new(), &joints, spheres, &[0.0, 0.0]).unwrap()
    }

    #[test]
    fn a_pose_inside_a_sphere_is_a_contact_and_one_clear_of_it_is_not() {
        // A sphere beside the upright arm's tip: upright it is 0.1 m clear; the arm bent by
        // 0.3 rad at its first joint sweeps its links through it.
        let sphere = ([0.2, 0.0, 0.9], 0.06);
        let mut r = replay(&[sphere]);
        for k in 0..20 {
            r.pose(k as f64 * 0.01, &[0.0, 0.0]);
        }
        let clear = r.report();
        assert!(clear.judged);
        assert_eq!(clear.obstacle_contact_periods, 0, "{clear:?}");
        let d = clear.smallest_distance_m.unwrap();
        assert!((d - 0.1).abs() < 1e-6, "{d}");
        let mut r = replay(&[sphere]);
        for k in 0..20 {
            r.pose(k as f64 * 0.01, &[0.3, 0.0]);
        }
        let hit = r.report();
        assert_eq!(hit.obstacle_contact_periods, 20, "{hit:?}");
        assert!(hit.smallest_distance_m.unwrap() < 0.0);
        assert_eq!(hit.first_contact_s, Some(0.0));
    }

    #[test]
    fn a_trajectory_for_other_joints_is_refused() {
        let path = std::env::temp_dir().join(format!("chaosd-replay-j-{}.xml", std::process::id()));
        std::fs::write(&path, ARM).unwrap();
        let joints = ["j1".to_string()];
        let e = Replay::new(&path, &BTreeMap::new(), &joints, &[], &[0.0, 0.0]);
        assert!(e.is_err());
    }
}
