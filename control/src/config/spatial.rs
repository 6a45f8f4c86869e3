//! The spatial set-up as a TOML file: which robot, which task, the law's gains, the feedback,
//! the limits and the run (docs/science.md, "Spatial arms"). `chaosctl config --preset panda` prints one.
//!
//! A file with a `[robot]` table is a spatial set-up; every planar config (no `[robot]`) keeps
//! its own format and meaning. The robot is named here but read by the caller (a built-in name
//! or a URDF path): this crate does no I/O. Limits come from the URDF, and the file may only
//! tighten them, so a typo cannot loosen what the arm's maker allows.

use super::Config;
use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::SpatialKinematics;
use crate::basics::invalid;
use crate::basics::ConfigError;
use crate::basics::MAX_JOINTS;
use crate::command::{DEFAULT_QDD_MAX, PANDA_QDD_MAX};
use crate::law::spatial::SpatialParams;
use crate::law::Secondary;
use crate::model::Chain;
use crate::safety::SafetyParams;
use crate::secondary::spatial::SphereSet;
use crate::secondary::spatial::MAX_SPHERES;
use crate::task::pose::SpatialTask;
use crate::task::pose::TaskKind;
use crate::task::Path;
use crate::task::Vec3;
use nalgebra::{Rotation3, SVector};

/// The Panda's ready pose, a comfortable start in the middle of its workspace.
pub const PANDA_READY: [f64; 7] = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];

pub use super::obstacles::SphereEntry;
pub use super::robot::{RobotSection, TaskSection};

fn positive(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, v, "a finite number > 0"))
    }
}

fn non_negative(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(field, v, "a finite number ≥ 0"))
    }
}

/// Whether a TOML text is a spatial set-up: a `[robot]` table that names a chain (not the
/// paper's planar arm, [`crate::config::planar_file::PLANAR_ROBOT`]).
pub fn is_spatial(text: &str) -> bool {
    text.parse::<toml::Table>()
        .map(|t| t.contains_key("robot") && !crate::config::planar_file::names_planar(&t))
        .unwrap_or(false)
}

/// Everything a run needs, checked against the robot.
#[derive(Debug, Clone, Copy)]
pub struct SpatialSetup<const N: usize> {
    pub arm: SpatialArm<N>,
    pub params: SpatialParams,
    pub q0: SVector<f64, N>,
    pub qd0: SVector<f64, N>,
    pub dt: f64,
    pub duration: f64,
    pub transient: f64,
}

impl<const N: usize> SpatialSetup<N> {
    /// The set-up's closed loop from its start, its delay line sized for its own τ.
    pub fn simulation(&self) -> crate::sim::Simulation<N, crate::tick_law::TickLaw<N>> {
        let p = self.params;
        crate::sim::Simulation::spatial(self.arm, p, self.dt, self.q0, self.qd0, p.core.tau)
    }
}

impl Config {
    /// The built-in spatial presets ([`SPATIAL_PRESETS`]): `panda`, the Panda's working set-up
    /// (docs/panda-study.md, "A set-up that is fast and robust": centring α = 160 with
    /// null-space damping k_d = 8 and the pull's speed capped at 1 rad/s, μ = 0.25 from t = 0,
    /// the path starting from rest over 1 s), and `panda-paper`, the paper's recipe on the same
    /// arm and path (centring α = 20 without damping, μ = 1 from t = 60 s): the chaotic
    /// self-motion the method was made for, and the slow capture the study measured.
    pub fn robot_preset(name: &str) -> Option<Self> {
        let mut c: Self = SPATIAL_PRESETS
            .contains(&name)
            .then(|| Self::from_robot_toml(PANDA_PAPER).expect("the panda preset parses"))?;
        if name == "panda" {
            // λ = −0.745 /s on the cycle by its Floquet multipliers; periodic inside every
            // position, speed, acceleration and jerk limit from 100 of 100 starts near the
            // ready pose and 71 of 98 across the joint box (`chaosctl starts`,
            // scripts/panda-study/basins.sh).
            c.law.alpha = 160.0;
            c.law.null_damping = 8.0;
            // Far from mid-range the pull asks several rad/s; capped, the first ticks stay
            // inside the acceleration limits. On the cycle the cap never acts.
            c.law.null_speed = 1.0;
            c.feedback.mu = 0.25;
            c.feedback.t_on = 0.0;
            // The hand starts at rest: the path comes up to speed over half a period.
            *c.task_ramp_mut() = 1.0;
        }
        Some(c)
    }

    /// One line for titles: robot, task, secondary task, projection.
    pub fn describe(&self) -> String {
        let r = self.spatial_part();
        format!(
            "{}: {} {} task, {} α = {}, projection {}",
            r.robot.description,
            r.task.kind,
            r.task.path,
            self.law.secondary,
            self.law.alpha,
            self.feedback.projection
        )
    }

    pub fn task_kind(&self) -> Result<TaskKind, ConfigError> {
        let r = self.spatial_part();
        match r.task.kind.as_str() {
            "position" => Ok(TaskKind::Position),
            "pose" => Ok(TaskKind::Pose),
            k => Err(invalid("task.kind", k, "\"position\" or \"pose\"")),
        }
    }

    fn check(&self) -> Result<(), ConfigError> {
        let r = self.spatial_part();
        positive("task.radius", r.task.radius)?;
        positive("task.period", r.task.period)?;
        positive("sim.dt", self.sim.dt)?;
        positive("sim.duration", self.sim.duration)?;
        if self.sim.duration > super::sim::MAX_DURATION {
            let most = format!("at most {} s", super::sim::MAX_DURATION);
            return Err(invalid("sim.duration", self.sim.duration, &most));
        }
        non_negative("sim.transient", self.sim.transient)?;
        self.sim.check_robot()?;
        self.law.check_robot()?;
        for (f, v) in [
            ("law.kp", self.law.kp),
            ("law.kv", self.law.kv),
            ("law.alpha", self.law.alpha),
            (
                "law.obstacle_weight",
                self.law.obstacle_weight.unwrap_or(0.0),
            ),
            ("law.null_damping", self.law.null_damping),
            ("law.null_speed", self.law.null_speed),
            ("law.damping_max", self.law.damping_max),
        ] {
            non_negative(f, v)?;
        }
        if self.law.null_speed > 0.0 && self.law.null_damping == 0.0 {
            return Err(invalid(
                "law.null_speed",
                self.law.null_speed,
                "0 while law.null_damping = 0 (the cap acts on the velocity α∇/k_d that damping pulls the self-motion to)",
            ));
        }
        // The planar arm's rules: the same gain may not mean a runaway on one arm and not the other.
        self.feedback.validate(self.sim.dt, r.task.period)?;
        positive("law.damping_threshold", self.law.damping_threshold)?;
        positive("law.track_loss", self.law.track_loss)?;
        let step = format!("sim.dt = {} s", self.sim.dt);
        crate::config::stability::check_sampled(
            &crate::config::stability::Sampled {
                prefix: "law",
                kp: self.law.kp,
                kv: self.law.kv,
                period: r.task.period,
                barriers: &[],
            },
            self.sim.dt,
            &step,
        )?;
        self.safety.check_robot()?;
        self.safety.validate_gains()?;
        if r.obstacles.len() > MAX_SPHERES {
            return Err(invalid(
                "obstacles",
                r.obstacles.len(),
                &format!("at most {MAX_SPHERES} spheres"),
            ));
        }
        for (i, o) in r.obstacles.iter().enumerate() {
            o.validate(&format!("obstacles[{i}]"))?;
        }
        Ok(())
    }

    fn per_joint(
        field: &str,
        v: &[f64],
        n: usize,
    ) -> Result<SVector<f64, MAX_JOINTS>, ConfigError> {
        if v.len() != n || !v.iter().all(|x| x.is_finite()) {
            return Err(invalid(
                field,
                v,
                &format!("{n} finite numbers, one per joint"),
            ));
        }
        crate::config::sim::check_start_size(field, v)?;
        Ok(SVector::from_fn(|i, _| v.get(i).copied().unwrap_or(0.0)))
    }

    fn secondary(&self) -> Result<Secondary, ConfigError> {
        let s = &self.law.secondary;
        s.task()
            .ok_or_else(|| invalid("law.secondary", s.name(), &Secondary::names()))
    }

    /// The limits: the URDF's, the published acceleration limits, tightened by the file.
    fn limits(&self, chain: &Chain) -> Result<SafetyParams, ConfigError> {
        let r = self.spatial_part();
        let n = chain.dof();
        self.safety.validate(n)?;
        let mut s = self.safety.params(n);
        let qdd: [f64; MAX_JOINTS] = match &self.safety.qdd_max {
            Some(v) => v.resolve(n),
            None if r.robot.description == "panda" && n == 7 => {
                std::array::from_fn(|i| PANDA_QDD_MAX.get(i).copied().unwrap_or(0.0))
            }
            None => [DEFAULT_QDD_MAX; MAX_JOINTS],
        };
        for (i, j) in chain.joints.iter().enumerate() {
            s.q_min[i] = j.limits.lower;
            s.q_max[i] = j.limits.upper;
            s.qd_max[i] = j.limits.velocity * self.safety.velocity_scale;
            if qdd[i].is_nan() || qdd[i] <= 0.0 {
                return Err(invalid("safety.qdd_max", qdd[i], "numbers > 0"));
            }
            s.qdd_max[i] = qdd[i];
            // The maker's published jerk limit, else the command interface's default ratio.
            s.jerk_max[i] = crate::command::MakerTable::for_robot(&r.robot.description, n)
                .and_then(|t| t.jerk.get(i).copied())
                .unwrap_or(crate::command::DEFAULT_JERK_PER_QDD * qdd[i]);
        }
        Ok(s)
    }

    /// The sampled-loop rules at a control step `dt` other than `sim.dt` (the daemon's period;
    /// `step` names it), with the barrier gains when the filter is on.
    pub fn check_step(&self, chain: &Chain, dt: f64, step: &str) -> Result<(), ConfigError> {
        let r = self.spatial_part();
        let safety = self.limits(chain)?;
        self.check_command(chain, dt)?;
        let barriers = [("safety.k1", safety.k1), ("safety.k_rate", safety.k_rate)];
        let g = crate::config::stability::Sampled {
            prefix: "law",
            kp: self.law.kp,
            kv: self.law.kv,
            period: r.task.period,
            barriers: if safety.enabled { &barriers } else { &[] },
        };
        crate::config::stability::check_sampled(&g, dt, step)
    }

    /// The command interface's generator at period `dt` (`N` = the chain's joint count): every
    /// `[command]` field checked against the chain, the PD gains at `dt`.
    pub fn generator<const N: usize>(
        &self,
        chain: &Chain,
        dt: f64,
    ) -> Result<crate::command::MotionGenerator<N>, ConfigError> {
        let r = self.spatial_part();
        let q0 = SVector::<f64, N>::from_fn(|i, _| self.sim.start().get(i).copied().unwrap_or(0.0));
        r.command
            .generator::<N>(chain, &r.robot.description, &q0, dt)
    }

    fn check_command(&self, chain: &Chain, dt: f64) -> Result<(), ConfigError> {
        crate::with_dof!(chain.dof(), N => self.generator::<N>(chain, dt).map(|_| ()))
    }

    /// Checks the file against `chain` and builds the run; `N` must be the chain's joint count.
    pub fn setup<const N: usize>(&self, chain: &Chain) -> Result<SpatialSetup<N>, ConfigError> {
        let r = self.spatial_part();
        self.check()?;
        let model = chain
            .model::<N>()
            .map_err(|e| invalid("robot.description", &r.robot.description, &e.to_string()))?;
        let mut arm = SpatialArm::new(model);
        arm.tool = Vec3::from(r.robot.tool);
        if !(arm.tool.iter().all(|v| v.is_finite()) && arm.tool.norm() <= MAX_TOOL_M) {
            return Err(invalid(
                "robot.tool",
                r.robot.tool,
                &format!("3 finite numbers, at most {MAX_TOOL_M} m from the tip link's origin"),
            ));
        }
        let radii = match &r.robot.link_radii {
            Some(r) => Self::per_joint("robot.link_radii", r, N)?,
            None => SVector::repeat(0.05),
        };
        if radii.iter().any(|&r| r < 0.0) {
            return Err(invalid("robot.link_radii", radii.as_slice(), "numbers ≥ 0"));
        }
        arm.radii = std::array::from_fn(|i| radii[i]);
        if let Some(capsules) = &r.robot.capsules {
            own_capsules(&mut arm, capsules, r.robot.link_radii.is_some())?;
        }
        let q0 = SVector::<f64, N>::from_column_slice(
            Self::per_joint("sim.q0", self.sim.start(), N)?
                .as_slice()
                .get(..N)
                .unwrap_or(&[]),
        );
        let qd0 = match &self.sim.qd0 {
            Some(v) => SVector::<f64, N>::from_column_slice(
                &Self::per_joint("sim.qd0", v, N)?.as_slice()[..N],
            ),
            None => SVector::zeros(),
        };
        let mut kin = SpatialKinematics::default();
        arm.kinematics(&q0, &qd0, &mut kin);
        let shape = r.task.path;
        let normal = Vec3::from(r.task.normal);
        let probe = Path::new(shape, Vec3::zeros(), normal, 1.0, 1.0)
            .ok_or_else(|| invalid("task.normal", r.task.normal, "a non-zero vector"))?;
        let center = match r.task.center {
            Some(c) => Vec3::from(c),
            None => kin.p - probe.position(0.0) * r.task.radius,
        };
        crate::config::check_ramp(r.task.ramp)?;
        let path = Path::new(shape, center, normal, r.task.radius, r.task.period)
            .ok_or_else(|| invalid("task.normal", r.task.normal, "a non-zero vector"))?
            .with_ramp(r.task.ramp);
        let orientation = match r.task.orientation_rpy {
            Some([r, p, y]) => Rotation3::from_euler_angles(r, p, y),
            None => Rotation3::from_matrix_unchecked(kin.rot),
        };
        check_reach(&arm, &path, chain.reach())?;
        let safety = self.limits(chain)?;
        self.check_step(chain, self.sim.dt, &format!("sim.dt = {} s", self.sim.dt))?;
        // At most MAX_SPHERES: validated above.
        let spheres: SphereSet = r.obstacles.iter().map(SphereEntry::to_ball).collect();
        let joint_weights = crate::law::metric::weights(&self.law.metric, &safety, chain.dof())?;
        let params = SpatialParams {
            core: self.law_core(self.secondary()?, safety),
            task: SpatialTask {
                kind: self.task_kind()?,
                path,
                orientation,
            },
            spheres,
            weight: self
                .law
                .obstacle_weight
                .unwrap_or(super::law::DEFAULT_WEIGHT),
            null_damping: self.law.null_damping,
            null_speed: self.law.null_speed,
            joint_weights,
            steer: None,
        };
        Ok(SpatialSetup {
            arm,
            params,
            q0,
            qd0,
            dt: self.sim.dt,
            duration: self.sim.duration,
            transient: self.sim.transient,
        })
    }
}

/// Every point of the path must lie within the chain's full stretch (plus the tool offset) of
/// joint 1: a path beyond it makes the law chase the target into a singularity.
fn check_reach<const N: usize>(
    arm: &SpatialArm<N>,
    path: &Path,
    reach: f64,
) -> Result<(), ConfigError> {
    let joint1 = arm.model.placement[0].pos;
    let limit = reach + arm.tool.norm();
    let far = (0..64)
        .map(|k| (path.position(path.period * k as f64 / 64.0) - joint1).norm())
        .fold(0.0, f64::max);
    if far > limit {
        return Err(invalid(
            "task.radius",
            path.radius,
            &format!(
                "the path reaches {far:.3} m from joint 1; the arm reaches at most {limit:.3} m (full stretch plus the tool)"
            ),
        ));
    }
    Ok(())
}

/// Names accepted by [`Config::robot_preset`].
pub const SPATIAL_PRESETS: &[&str] = &["panda", "panda-paper"];

/// The farthest a tool point may sit from its tip link (m): past it the last capsule and the
/// tool's lever are no arm's (a 1e308 m tool overflowed the capsule's length to infinity).
pub const MAX_TOOL_M: f64 = 10.0;

/// `robot.capsules` onto `arm`: one per link, each end at most [`MAX_TOOL_M`] from its link's
/// origin, radii ≥ 0, and not beside `robot.link_radii` (two radii for one link).
fn own_capsules<const N: usize>(
    arm: &mut SpatialArm<N>,
    capsules: &[super::robot::CapsuleEntry],
    radii_given: bool,
) -> Result<(), ConfigError> {
    const KEY: &str = "robot.capsules";
    if radii_given {
        return Err(invalid(
            KEY,
            "given",
            "either robot.link_radii (capsules about the joint origins) or robot.capsules, not both",
        ));
    }
    if capsules.len() != N {
        return Err(invalid(
            KEY,
            capsules.len(),
            &format!("one capsule per link: {N} for this chain"),
        ));
    }
    let mut ends = [[Vec3::zeros(); 2]; N];
    for (j, c) in capsules.iter().enumerate() {
        let near =
            |p: &[f64; 3]| p.iter().all(|v| v.is_finite()) && Vec3::from(*p).norm() <= MAX_TOOL_M;
        if !(near(&c.a) && near(&c.b)) {
            return Err(invalid(
                &format!("{KEY}[{j}]"),
                format!("a = {:?}, b = {:?}", c.a, c.b),
                &format!(
                    "end points of 3 finite numbers, at most {MAX_TOOL_M} m from the link's origin"
                ),
            ));
        }
        if !(c.radius.is_finite() && c.radius >= 0.0) {
            return Err(invalid(
                &format!("{KEY}[{j}].radius"),
                c.radius,
                "a radius ≥ 0 (m)",
            ));
        }
        // The link's URDF frame is body j's turned by `turn` (its axis onto z).
        let into_body = arm.model.turn[j].transpose();
        ends[j] = [into_body * Vec3::from(c.a), into_body * Vec3::from(c.b)];
        arm.radii[j] = c.radius;
    }
    arm.ends = Some(ends);
    Ok(())
}

/// The paper's recipe on the Panda (docs/panda-study.md), preset `panda-paper`: a 0.15 m circle
/// in the vertical plane in front of the Panda, position task, joint-limit centring α = 20,
/// feedback μ = 1 projected into the null space from t = 60 s, the safety filter on. It starts
/// off the cycle (a small kick on joints 1 and 3) and runs 60 s without feedback first. The
/// `panda` preset is this with the gain study's stabiliser.
pub const PANDA_PAPER: &str = r#"
[robot]
description = "panda"
tool = [0.0, 0.0, 0.1034]
link_radii = [0.08, 0.08, 0.07, 0.07, 0.07, 0.06, 0.05]

[task]
kind = "position"
path = "circle"
normal = [1.0, 0.0, 0.0]
radius = 0.15
period = 2.0

[law]
kp = 40.0
kv = 15.0
alpha = 20.0
secondary = "centring"

[feedback]
mu = 1.0
t_on = 60.0
projection = "null-space"

[safety]
enabled = true

[sim]
dt = 0.001
duration = 200.0
transient = 5.0
q0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
qd0 = [0.1, 0.0, -0.1, 0.0, 0.0, 0.0, 0.0]
"#;
