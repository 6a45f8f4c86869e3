//! MuJoCo as the plant: the arm simulated by a physics engine whose model is not chaosd's.
//!
//! Every other plant shares chaosd's own model of the arm, so a controller right only about
//! that model cannot be caught, and "no link touched an obstacle" is judged by the very
//! capsules the filter keeps apart. Here MuJoCo integrates the robot as its URDF (or MJCF)
//! describes it, meshes and all, with its own inertials, joint damping and contact; chaosd's
//! commands reach it as a robot's controller would apply them, and MuJoCo's collision
//! detection is the judge ([`judge`]).
//!
//! How each interface maps onto MuJoCo (torques as `qfrc_applied`, recomputed every physics
//! step from the state MuJoCo's first stage computed, `mj_step1`/`mj_step2`):
//! * torque: as sent, clamped to the arm's effort limits;
//! * acceleration: MuJoCo's own inverse dynamics, M(q)q̈ + bias − passive forces, for the
//!   ramped q̈ + q⃛·s (a perfect inner loop on the true model);
//! * position and velocity: a joint servo (PD on the reference plus MuJoCo's bias forces) at
//!   `[plant.rigid_body]`'s bandwidth on MuJoCo's own joint inertia, the set-point moving on
//!   as the rigid-body plant's does; velocity mode integrates its own set-point;
//! * hold and brake: the servo holds the position reached.
//!
//! Joints of the model that are not chaosd's (a gripper's fingers) are welded where they stand,
//! and pairs of the arm's bodies that touch in the start pose never collide ([`load`]).
//! Only this module and `chaosd-plant-mujoco` link MuJoCo (feature `mujoco`).

pub mod fit;
pub mod judge;
pub mod load;
pub mod replay;
pub mod scene;
mod servo;

use crate::config::PlantConfig;
use crate::report::ContactReport;
use crate::seam::{Actuation, Plant, PlantError};
use anyhow::{bail, Result};
use control::System;
use mujoco_rs::mujoco_c::{mjModel, mj_forward, mj_mulM, mj_step1, mj_step2};
use mujoco_rs::prelude::*;
use protocol::{flags, StateSample};

/// The most simulated time one `read` integrates after a stall (s), as the built-in simulator.
const MAX_CATCH_UP_S: f64 = crate::sim::MAX_CATCH_UP_S;

/// What the joints are asked to do.
#[derive(Clone, Copy, PartialEq)]
enum Drive {
    Torque,
    Ramp,
    Track,
    Hold,
}

pub struct MujocoPlant {
    data: MjData<Box<MjModel>>,
    arm: Vec<(usize, usize)>,
    /// Servo gains per joint.
    kp: Vec<f64>,
    kd: Vec<f64>,
    tau_max: Vec<f64>,
    drive: Drive,
    /// Drive inputs: the torque, the ramp's q̈ and q⃛, or the tracked reference (q, q̇).
    a: Vec<f64>,
    b: Vec<f64>,
    /// Velocity mode's own set-point.
    set_point: Vec<f64>,
    /// Whether velocity mode's set-point is in use (sized at start: no allocation on a switch).
    rate_set: bool,
    /// Where the drive's reference is at the start of the current period (s after its start).
    offset: f64,
    hold_at: Vec<f64>,
    holding: bool,
    /// Scratch: per-dof acceleration in, M·q̈ out.
    acc: Vec<f64>,
    macc: Vec<f64>,
    applied: Vec<f64>,
    substeps: u32,
    h: f64,
    period: f64,
    clamps: u64,
    braking: bool,
    /// The model's own joint damping, and whether the servo's K_d is added to it now.
    damping: Vec<f64>,
    servo_damped: bool,
    /// The obstacle geoms (one per sphere slot), the daemon's namespace, and the helper that
    /// follows the daemon's list while the plant runs.
    obstacles: Vec<usize>,
    names: protocol::ServiceNames,
    start_scene: scene::Spheres,
    sync: Option<(scene::SceneSync, std::sync::mpsc::Receiver<scene::Spheres>)>,
    avoid_core: Option<usize>,
    judge: judge::Judge,
}

impl MujocoPlant {
    /// The arm `launch` describes, in the model `[plant.mujoco]` names (default: the set-up's
    /// own robot), at rest in the set-up's start pose.
    pub fn from_launch(system: &System, cfg: &PlantConfig) -> Result<Self> {
        let Some(s) = system.robot() else {
            bail!(
                "plant.dynamics = \"mujoco\" simulates a robot's URDF; the paper's planar arm has \
                 no mass model (name robots/planar3.urdf in [robot] to run it as a chain)"
            );
        };
        let chain = &s.chain;
        let n = chain.dof();
        let joints: Vec<String> = chain.joints.iter().map(|j| j.name.clone()).collect();
        let spheres: Vec<([f64; 3], f64)> = s
            .own()
            .obstacles
            .iter()
            .map(|o| (o.center, o.radius))
            .collect();
        let period = cfg.period_ns() as f64 * 1e-9;
        let h = period / f64::from(cfg.substeps);
        let own;
        let source = match &cfg.mujoco.model {
            Some(p) => load::Source::File(p),
            None => match control::model::builtin(&s.own().robot.description) {
                Ok(text) => load::Source::Urdf(text),
                Err(_) => {
                    own = std::path::PathBuf::from(&s.own().robot.description);
                    load::Source::File(&own)
                }
            },
        };
        let q0 = s.config.sim.start();
        let built = load::build(source, &cfg.mujoco.packages, (&spheres, q0), &joints, h)?;
        for name in &built.welded {
            tracing::info!(
                "MuJoCo: the model's joint {name:?} is not chaosd's: welded where it stands"
            );
        }
        for (a, b) in &built.excluded {
            tracing::info!(
                "MuJoCo: {a} and {b} touch in the start pose: that pair is excluded from contact"
            );
        }
        let limits = control::with_dof!(n, N => {
            s.own().command.limits::<N>(chain, &s.own().robot.description)?.tau.to_vec()
        });
        let excluded = built.excluded.len();
        let mut data = MjData::new(built.model);
        let m: *const mjModel = data.model().ffi();
        // SAFETY: the data owns the model, which outlives both references here; the addresses
        // written come from the model's joint table.
        let (m, d) = unsafe { (&*m, data.ffi_mut()) };
        let nv = m.nv as usize;
        for (i, &(qa, _)) in built.arm.iter().enumerate() {
            unsafe { *d.qpos.add(qa) = q0[i] };
        }
        unsafe { mj_forward(m, d) };
        let rb = &cfg.rigid_body;
        let dofs: Vec<usize> = built.arm.iter().map(|a| a.1).collect();
        let (kp_all, kd_all) = servo::gains(
            &servo::inverse_inertia(m, d, &dofs),
            std::f64::consts::TAU * rb.servo_bandwidth_hz,
            rb.servo_damping,
            h,
        );
        let pick = |given: &Option<Vec<f64>>, derived: &[f64]| {
            given.clone().unwrap_or_else(|| derived[..n].to_vec())
        };
        let kp = pick(&rb.servo_kp, &kp_all);
        let kd = pick(&rb.servo_kd, &kd_all);
        let start_scene = scene::Spheres::of(&spheres);
        let mut judge = judge::Judge::new(m, built.obstacles.clone(), excluded);
        judge.set_active(start_scene.n);
        judge.set_outside_capsules(outside_capsules(s, source, cfg, &joints, q0)?);
        // SAFETY: dof_damping has nv entries; the arm's dofs are below nv.
        let built_damping = built
            .arm
            .iter()
            .map(|&(_, da)| unsafe { *m.dof_damping.add(da) })
            .collect();
        Ok(Self {
            arm: built.arm,
            kp,
            kd,
            tau_max: limits,
            drive: Drive::Hold,
            a: vec![0.0; n],
            b: vec![0.0; n],
            set_point: vec![0.0; n],
            rate_set: false,
            offset: 0.0,
            hold_at: q0[..n].to_vec(),
            holding: false,
            acc: vec![0.0; nv],
            macc: vec![0.0; nv],
            applied: vec![0.0; n],
            substeps: cfg.substeps,
            h,
            period,
            clamps: 0,
            braking: true,
            damping: built_damping,
            servo_damped: false,
            obstacles: built.obstacles,
            names: protocol::ServiceNames::new(&cfg.namespace)?,
            start_scene,
            sync: None,
            avoid_core: cfg.core,
            judge,
            data,
        })
    }

    /// One physics step: MuJoCo's first stage, the torques, its second stage.
    fn substep(&mut self, since: f64) {
        let m: *const mjModel = self.data.model().ffi();
        // SAFETY: the model outlives the data (it owns it), and nothing else touches either.
        let (m, d) = unsafe { (&*m, self.data.ffi_mut()) };
        unsafe { mj_step1(m, d) };
        let n = self.arm.len();
        let q = |qa: usize| unsafe { *d.qpos.add(qa) };
        let v = |da: usize| unsafe { *d.qvel.add(da) };
        let bias = |da: usize| unsafe { *d.qfrc_bias.add(da) };
        if self.drive == Drive::Ramp {
            self.acc.iter_mut().for_each(|x| *x = 0.0);
            for i in 0..n {
                self.acc[self.arm[i].1] = self.a[i] + self.b[i] * since.max(0.0);
            }
            // SAFETY: both buffers have nv entries; qM is current after mj_step1.
            unsafe { mj_mulM(m, d, self.macc.as_mut_ptr(), self.acc.as_ptr()) };
        }
        if self.drive != Drive::Hold {
            self.holding = false;
        } else if !self.holding {
            self.holding = true;
            for i in 0..n {
                self.hold_at[i] = q(self.arm[i].0);
            }
        }
        let mut clamped = false;
        for i in 0..n {
            let (qa, da) = self.arm[i];
            let wanted = match self.drive {
                Drive::Torque => self.a[i],
                Drive::Ramp => self.macc[da] + bias(da) - unsafe { *d.qfrc_passive.add(da) },
                Drive::Track => {
                    let at = self.a[i] + self.b[i] * since;
                    bias(da) + self.kp[i] * (at - q(qa)) + self.kd[i] * (self.b[i] - v(da))
                }
                Drive::Hold => {
                    bias(da) + self.kp[i] * (self.hold_at[i] - q(qa)) - self.kd[i] * v(da)
                }
            };
            let tau = wanted.clamp(-self.tau_max[i], self.tau_max[i]);
            clamped |= tau != wanted;
            self.applied[i] = tau;
            // The servo's −K_d·q̇ is MuJoCo's joint damping (integrated implicitly, so the
            // servo holds at any pose); the force applied is the rest of the motor's torque.
            let damped = if self.servo_damped {
                self.kd[i] * v(da)
            } else {
                0.0
            };
            unsafe { *d.qfrc_applied.add(da) = tau + damped };
        }
        if clamped && self.drive != Drive::Hold {
            self.clamps += 1;
        }
        unsafe { mj_step2(m, d) };
    }

    /// Puts the servo's K_d into MuJoCo's joint damping while the servo drives the arm (position,
    /// velocity, hold), and takes it out while torques or accelerations do.
    fn set_servo_damping(&mut self) {
        let on = matches!(self.drive, Drive::Track | Drive::Hold);
        if on == self.servo_damped {
            return;
        }
        self.servo_damped = on;
        // SAFETY: the data owns its model; only dof_damping of the arm's dofs changes, between
        // steps (MuJoCo reads the model afresh each step).
        let m = unsafe { self.data.model_mut().ffi_mut() };
        for (i, &(_, da)) in self.arm.iter().enumerate() {
            let extra = if on { self.kd[i] } else { 0.0 };
            unsafe { *m.dof_damping.add(da) = self.damping[i] + extra };
        }
    }

    /// Moves MuJoCo's spheres to the daemon's newest list, if it changed (between two periods).
    fn follow_scene(&mut self) {
        let Some(now) = self.sync.as_ref().and_then(|(_, rx)| rx.try_recv().ok()) else {
            return;
        };
        // SAFETY: the data owns its model; geom and body ids are below ngeom and nbody, each
        // obstacle geom's body is a mocap body, and MuJoCo reads these fields afresh every step.
        let d: *mut mujoco_rs::mujoco_c::mjData = unsafe { self.data.ffi_mut() };
        let m = unsafe { self.data.model_mut().ffi_mut() };
        for (i, &g) in self.obstacles.iter().enumerate() {
            let (c, r) = if i < now.n { now.s[i] } else { load::PARKED };
            unsafe {
                let mocap = *m.body_mocapid.add(*m.geom_bodyid.add(g) as usize) as usize;
                for (k, x) in c.iter().enumerate() {
                    *(*d).mocap_pos.add(3 * mocap + k) = *x;
                    *m.geom_aabb.add(6 * g + 3 + k) = r;
                }
                *m.geom_size.add(3 * g) = r;
                *m.geom_rbound.add(g) = r;
            }
        }
        self.judge.set_active(now.n);
        self.judge.scene_changed();
    }

    /// Advances one period.
    fn period_step(&mut self) {
        self.set_servo_damping();
        let k = self.h;
        for s in 0..self.substeps {
            self.substep(self.offset + k * f64::from(s));
        }
        if self.rate_set && self.drive == Drive::Track {
            for (p, r) in self.set_point.iter_mut().zip(&self.b) {
                *p += r * self.period;
            }
        }
        self.offset += self.period;
    }

    fn arm_q(&self, i: usize) -> f64 {
        // SAFETY: an address from the model's joint table.
        unsafe { *self.data.ffi().qpos.add(self.arm[i].0) }
    }

    fn fits(&self, slices: &[&[f64]], since: f64) -> bool {
        slices.iter().all(|s| s.len() == self.arm.len()) && since.is_finite()
    }
}

impl Plant for MujocoPlant {
    fn n(&self) -> usize {
        self.arm.len()
    }

    fn flags(&self) -> u32 {
        flags::SIMULATED | if self.braking { flags::BRAKING } else { 0 }
    }

    fn activate(&mut self) -> Result<(), PlantError> {
        let started =
            scene::SceneSync::start(self.names.clone(), self.start_scene, self.avoid_core);
        self.sync = Some(started.map_err(|e| PlantError::Activation {
            what: "cannot start the thread that follows the daemon's obstacles",
            source: Box::new(e),
        })?);
        Ok(())
    }

    fn write(&mut self, actuation: Actuation<'_>) -> Result<(), PlantError> {
        self.braking = false;
        if !matches!(actuation, Actuation::Velocity { .. }) {
            self.rate_set = false;
        }
        match actuation {
            Actuation::Torque { tau, since, .. } if self.fits(&[tau], since) => {
                self.a.copy_from_slice(tau);
                self.drive = Drive::Torque;
                self.offset = since.max(0.0);
            }
            Actuation::Accelerate {
                qdd, qddd, since, ..
            } if self.fits(&[qdd, qddd], since) => {
                self.a.copy_from_slice(qdd);
                self.b.copy_from_slice(qddd);
                self.drive = Drive::Ramp;
                self.offset = since.max(0.0);
            }
            Actuation::Position { q, qd, since, .. } if self.fits(&[q, qd], since) => {
                // Reached one period after the answered state: the reference runs from a
                // period before that.
                self.a.copy_from_slice(q);
                self.b.copy_from_slice(qd);
                self.drive = Drive::Track;
                self.offset = since.max(0.0) - self.period;
            }
            Actuation::Velocity { qd, since, .. } if self.fits(&[qd], since) => {
                if !self.rate_set {
                    for i in 0..self.arm.len() {
                        self.set_point[i] = self.arm_q(i);
                    }
                    self.rate_set = true;
                }
                self.a.copy_from_slice(&self.set_point);
                self.b.copy_from_slice(qd);
                self.drive = Drive::Track;
                self.offset = 0.0;
            }
            _ => {
                self.braking = true;
                self.drive = Drive::Hold;
            }
        }
        Ok(())
    }

    fn read(&mut self, elapsed: f64, out: &mut StateSample) -> Result<(), PlantError> {
        self.follow_scene();
        if elapsed > 0.0 {
            let periods = (elapsed.min(MAX_CATCH_UP_S) / self.period).round().max(1.0) as u64;
            for _ in 0..periods {
                self.period_step();
                let m: *const mjModel = self.data.model().ffi();
                let t = self.data.ffi().time;
                // SAFETY: the model outlives the data that owns it.
                let (m, d) = unsafe { (&*m, self.data.ffi_mut()) };
                self.judge.observe(m, d, t);
            }
        }
        let d = self.data.ffi();
        let n = self.arm.len();
        out.n = n as u32;
        for (i, &(qa, da)) in self.arm.iter().enumerate() {
            // SAFETY: addresses from the model's joint table.
            let (q, qd) = unsafe { (*d.qpos.add(qa), *d.qvel.add(da)) };
            if !(q.is_finite() && qd.is_finite()) {
                return Err(PlantError::Fault {
                    what: "MuJoCo's state is not finite",
                    source: None,
                });
            }
            out.q[i] = q;
            out.qd[i] = qd;
            out.tau[i] = self.applied[i];
        }
        Ok(())
    }

    fn deactivate(&mut self) {
        self.drive = Drive::Hold;
        self.sync = None;
    }

    fn stamp(&self, nominal_ns: u64, _now_ns: u64) -> u64 {
        nominal_ns
    }

    fn effort_clamps(&self) -> u64 {
        self.clamps
    }

    fn contacts(&self) -> Option<ContactReport> {
        Some(self.judge.report(self.data.model().ffi()))
    }
}

/// How far the model's geometry reaches out of the set-up's capsules, on the link where it
/// reaches farthest (1-based, m), if anywhere by more than a millimetre: measured once at the
/// start pose (a capsule is rigid with its link), and said in the log with the remedy.
fn outside_capsules(
    s: &control::system::SpatialSystem,
    source: load::Source<'_>,
    cfg: &PlantConfig,
    joints: &[String],
    q0: &[f64],
) -> Result<Option<(usize, f64)>> {
    let chain = &s.chain;
    let (segments, radii) = control::with_dof!(chain.dof(), N => {
        let setup = s.config.setup::<N>(chain)?;
        let mut k = control::arm::spatial::SpatialKinematics::<N>::default();
        setup.arm.kinematics(&setup.q0, &control::VecN::<N>::zeros(), &mut k);
        let all = setup.arm.capsule_segments(&k);
        let segments: Vec<[[f64; 3]; 2]> = all[..N]
            .iter()
            .map(|[a, b]| [[a.x, a.y, a.z], [b.x, b.y, b.z]])
            .collect();
        (segments, setup.arm.radii.to_vec())
    });
    let fits = fit::fit_segments(
        source,
        &cfg.mujoco.packages,
        joints,
        &q0[..joints.len()],
        &segments,
    )?;
    let worst = fits
        .iter()
        .zip(&radii)
        .enumerate()
        .filter(|(_, (f, _))| f.geoms > 0)
        .map(|(j, (f, r))| (j + 1, f.radius - r))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    Ok(match worst {
        Some((link, out)) if out > 1e-3 => {
            tracing::warn!(
                "MuJoCo: the model's geometry reaches {out:.3} m out of the set-up's capsule on \
                 link {link}: the filter keeps the capsules clear, so that link can touch where \
                 it reports clearance (`chaosctl robot fit-radii ROBOT --mujoco-model MODEL \
                 --capsules` fits capsules that hold the geometry)"
            );
            Some((link, out))
        }
        _ => None,
    })
}
