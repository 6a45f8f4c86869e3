//! `[command]`: which interface the daemon sends and how the stream is limited.

use crate::arm::VecN;
use crate::basics::invalid;
use crate::basics::ConfigError;
use crate::command::{
    CommandGains, CommandMode, JointLimits, LimitOverrides, Limiter, MakerTable, MotionGenerator,
};
use crate::model::Chain;
use crate::rigid_body::ServoGains;
use serde::{Deserialize, Serialize};

/// The default derating of every limit (2 %).
pub const DEFAULT_MARGIN: f64 = 0.02;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CommandSection {
    /// "acceleration", "velocity", "position" or "torque". Changing it takes a restart.
    pub mode: CommandMode,
    /// Pass every command through the limiter (off only to show what it prevents).
    pub limiter: bool,
    /// Every limit is derated by this fraction (0 ≤ margin < 0.5).
    pub margin: f64,
    /// Torque mode's joint PD: each joint's natural frequency (Hz) and damping ratio on its
    /// inertia at the start, unless `kp`/`kd` give gains (N·m/rad, N·m·s/rad).
    pub pd_bandwidth_hz: f64,
    pub pd_damping: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kp: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kd: Option<Vec<f64>>,
    /// Velocity mode's position correction (1/s): the rate sent is the reference's mean rate over the period plus
    /// `velocity_kp·(q_r − q)`, so the arm's position follows the reference and does not drift.
    /// 0 sends the reference's rate alone.
    pub velocity_kp: f64,
    /// Velocity mode's integral term (1/s²): `velocity_ki·∫(q_r − q)dt` is added to the pull,
    /// which takes back the arm's servo lag behind an accelerating reference (a P term alone
    /// leaves half of it). 0: a P pull alone.
    pub velocity_ki: f64,
    /// Tighter limits than the description's.
    #[serde(skip_serializing_if = "is_default")]
    pub limits: LimitOverrides,
}

/// Velocity mode's default pull back to the reference (1/s): a 0.2 s time constant, half the
/// gain at which the Panda and Baxter, offline, start to hunt on a slow coupled mode of their
/// servos (docs/commanding.md).
pub const DEFAULT_VELOCITY_KP: f64 = 5.0;

/// Velocity mode's default integral gain (1/s²): offline with k_v = 5 the Panda's pull starts
/// to hunt between 200 and 300, Baxter's between 300 and 600, TIAGo's above 600; 100 keeps a
/// factor of two to the first and takes the Panda's tracking from 0.34 to 0.075 mm
/// (docs/commanding.md).
pub const DEFAULT_VELOCITY_KI: f64 = 100.0;

fn is_default(o: &LimitOverrides) -> bool {
    *o == LimitOverrides::default()
}

impl Default for CommandSection {
    fn default() -> Self {
        Self {
            mode: CommandMode::Acceleration,
            limiter: true,
            margin: DEFAULT_MARGIN,
            pd_bandwidth_hz: 10.0,
            pd_damping: 1.0,
            kp: None,
            kd: None,
            velocity_kp: DEFAULT_VELOCITY_KP,
            velocity_ki: DEFAULT_VELOCITY_KI,
            limits: LimitOverrides::default(),
        }
    }
}

fn gains<const N: usize>(field: &str, v: &[f64]) -> Result<VecN<N>, ConfigError> {
    if v.len() != N || !v.iter().all(|x| x.is_finite() && *x >= 0.0) {
        return Err(invalid(
            field,
            v,
            &format!("{N} finite numbers ≥ 0, one per joint"),
        ));
    }
    Ok(VecN::<N>::from_column_slice(v))
}

impl CommandSection {
    /// The margin derates the position range too: a start posture outside what is left would
    /// have the limiter hold the arm against a bound from the first tick, tracking nothing.
    fn start_inside<const N: usize>(
        &self,
        limiter: &Limiter<N>,
        q0: &VecN<N>,
    ) -> Result<(), ConfigError> {
        let l = limiter.limits();
        match (0..N).find(|&i| q0[i] < l.q_min[i] || q0[i] > l.q_max[i]) {
            None => Ok(()),
            Some(i) => Err(invalid(
                "command.margin",
                self.margin,
                &format!(
                    "a margin that leaves the start posture inside the range it allows: joint {} starts at {:.3} rad, outside [{:.3}, {:.3}]",
                    i + 1,
                    q0[i],
                    l.q_min[i],
                    l.q_max[i]
                ),
            )),
        }
    }

    /// The limits the stream obeys: the description's (`robot` names a maker's table), tightened
    /// by `[command.limits]`.
    pub fn limits<const N: usize>(
        &self,
        chain: &Chain,
        robot: &str,
    ) -> Result<JointLimits<N>, ConfigError> {
        JointLimits::<N>::described(chain, MakerTable::for_robot(robot, N))
            .tightened(&self.limits, "command.limits")
    }

    /// The daemon's generator at period `dt` for `chain` starting at `q0`, with every field
    /// checked (the PD gains must be stable at `dt` on the arm's inertia).
    pub fn generator<const N: usize>(
        &self,
        chain: &Chain,
        robot: &str,
        q0: &VecN<N>,
        dt: f64,
    ) -> Result<MotionGenerator<N>, ConfigError> {
        if !(self.margin.is_finite() && (0.0..0.5).contains(&self.margin)) {
            return Err(invalid(
                "command.margin",
                self.margin,
                "a fraction in [0, 0.5)",
            ));
        }
        for (f, v) in [
            ("command.pd_bandwidth_hz", self.pd_bandwidth_hz),
            ("command.pd_damping", self.pd_damping),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(f, v, "a number > 0"));
            }
        }
        let kv_max = 0.5 / dt;
        let kv = self.velocity_kp;
        if self.mode == CommandMode::Velocity && !(kv.is_finite() && (0.0..=kv_max).contains(&kv)) {
            return Err(invalid(
                "command.velocity_kp",
                kv,
                &format!("a rate in [0, {kv_max:.0}] 1/s (half the loop's rate: the correction acts once a period)"),
            ));
        }
        let ki_max = kv_max * kv_max;
        let ki = self.velocity_ki;
        if self.mode == CommandMode::Velocity && !(ki.is_finite() && (0.0..=ki_max).contains(&ki)) {
            return Err(invalid(
                "command.velocity_ki",
                ki,
                &format!("a gain in [0, {ki_max:.0}] 1/s² (the square of velocity_kp's bound)"),
            ));
        }
        let limits = self.limits::<N>(chain, robot)?;
        let model = chain
            .model::<N>()
            .map_err(|e| invalid("robot.description", robot, &e.to_string()))?;
        if self.mode == CommandMode::Torque {
            let instead = ", or use command.mode = \"acceleration\"";
            if let Some(e) = chain.massless_joint(instead) {
                return Err(e.into());
            }
            if let Some(e) =
                chain.gravity_beyond_effort(&model, q0, &VecN::<N>::from(limits.tau), instead)
            {
                return Err(e.into());
            }
        }
        let ms = crate::rigid_body::inertias(&model, chain, q0);
        let auto = ServoGains::from_bandwidth(&ms, self.pd_bandwidth_hz, self.pd_damping);
        let g = CommandGains {
            kp: match &self.kp {
                Some(v) => gains::<N>("command.kp", v)?,
                None => auto.kp,
            },
            kd: match &self.kd {
                Some(v) => gains::<N>("command.kd", v)?,
                None => auto.kd,
            },
            kv: VecN::<N>::repeat(self.velocity_kp),
            ki: VecN::<N>::repeat(self.velocity_ki),
        };
        if self.mode == CommandMode::Torque {
            let kp = if self.kp.is_some() {
                "command.kp"
            } else {
                "command.pd_bandwidth_hz"
            };
            let kd = if self.kd.is_some() {
                "command.kd"
            } else {
                "command.pd_bandwidth_hz"
            };
            if self.kp.is_none() && self.kd.is_none() {
                ServoGains::check_bandwidth(
                    &ms,
                    self.pd_bandwidth_hz,
                    self.pd_damping,
                    dt,
                    "command.pd_bandwidth_hz",
                )?;
            } else {
                ServoGains { kp: g.kp, kd: g.kd }.check(&ms, dt, kp, kd)?;
            }
        }
        let limiter = Limiter::new(&limits, dt, self.margin, self.limiter);
        if self.limiter {
            self.start_inside(&limiter, q0)?;
        }
        MotionGenerator::new(self.mode, limiter, g, Some(model))
            .map_err(|e| invalid("command.mode", self.mode.name(), e))
    }
}
