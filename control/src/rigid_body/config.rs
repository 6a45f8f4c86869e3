//! `[plant.rigid_body]`: the simulated arm's physics, checked at start-up.

use super::{mismatched, RigidBody, Sensor};
use crate::arm::VecN;
use crate::basics::invalid;
use crate::basics::ConfigError;
use crate::model::{Chain, Model};
use serde::{Deserialize, Serialize};

/// A joint servo's gains, per joint (N·m/rad, N·m·s/rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoGains<const N: usize> {
    pub kp: VecN<N>,
    pub kd: VecN<N>,
}

/// Joint inertia (N×N).
pub type Inertia<const N: usize> = nalgebra::SMatrix<f64, N, N>;

impl<const N: usize> ServoGains<N> {
    /// Gains that give each joint the natural frequency `hz` and damping ratio `zeta` on the
    /// smallest inertia it shows in any of the postures whose inertias are `ms`: the inertia it
    /// has when the other joints move freely, 1/(M⁻¹)ᵢᵢ. No coupled mode of the arm then runs far
    /// above `hz` anywhere (joints whose axes line up share a light, fast mode).
    pub fn from_bandwidth(ms: &[Inertia<N>], hz: f64, zeta: f64) -> Self {
        let w = std::f64::consts::TAU * hz;
        let mut apparent = VecN::<N>::repeat(f64::INFINITY);
        for m in ms {
            let a = m
                .try_inverse()
                .map(|inv| inv.diagonal().map(|x| 1.0 / x))
                .unwrap_or_else(|| m.diagonal());
            apparent = apparent.zip_map(&a, f64::min);
        }
        Self {
            kp: apparent * (w * w),
            kd: apparent * (2.0 * zeta * w),
        }
    }

    /// [`Self::check`] for gains set by a bandwidth (`field`, Hz): the error names the highest
    /// bandwidth the servo can hold at step `h`, not the gains it came to.
    pub fn check_bandwidth(
        ms: &[Inertia<N>],
        hz: f64,
        zeta: f64,
        h: f64,
        field: &str,
    ) -> Result<(), ConfigError> {
        let stable = |hz: f64| {
            Self::from_bandwidth(ms, hz, zeta)
                .check(ms, h, "", "")
                .is_ok()
        };
        if stable(hz) {
            return Ok(());
        }
        // Gains grow with the bandwidth: bisect for the stability bound (start-up only).
        let (mut lo, mut hi) = (0.0, hz);
        for _ in 0..30 {
            let mid = 0.5 * (lo + hi);
            if stable(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Err(invalid(
            field,
            hz,
            &format!(
                "at most {lo:.1} Hz at this damping: above it the arm's fastest mode makes the \
                 servo unstable at its {:.0} Hz rate",
                1.0 / h
            ),
        ))
    }

    /// Refuses gains a discrete servo at step `h` cannot run stably on an arm whose inertia, in
    /// the postures tried, is each of `ms`. Joint servos couple through M, so the test is on the
    /// arm's modes, the eigenvalues λ of M⁻¹K: with a factor of ~4 to spare,
    /// λ(M⁻¹K_d)·h ≤ 0.5 and λ(M⁻¹K_p)·h² ≤ 0.1. The error names the field (`kp`, `kd`) and
    /// the joint that moves most in the fastest mode.
    pub fn check(&self, ms: &[Inertia<N>], h: f64, kp: &str, kd: &str) -> Result<(), ConfigError> {
        for (field, k) in [(kp, &self.kp), (kd, &self.kd)] {
            if !k.iter().all(|v| v.is_finite() && *v >= 0.0) {
                return Err(invalid(field, k.as_slice(), "finite gains ≥ 0"));
            }
        }
        for m in ms {
            self.check_one(m, h, kp, kd)?;
        }
        Ok(())
    }

    fn check_one(&self, m: &Inertia<N>, h: f64, kp: &str, kd: &str) -> Result<(), ConfigError> {
        let inv = m.try_inverse().ok_or_else(|| {
            invalid(
                "robot.description",
                "singular inertia",
                "a chain whose joints all carry mass",
            )
        })?;
        for (field, k, bound, power) in [(kd, &self.kd, 0.5, 1), (kp, &self.kp, 0.1, 2)] {
            let root = k.map(f64::sqrt);
            let a = Inertia::<N>::from_diagonal(&root) * inv * Inertia::<N>::from_diagonal(&root);
            // At start-up only: a dynamic matrix, since the fixed-size eigen solver needs
            // bounds a const generic cannot give.
            let eig = nalgebra::DMatrix::from_column_slice(N, N, a.as_slice()).symmetric_eigen();
            let (i, lambda) = eig.eigenvalues.argmax();
            let x = lambda * h.powi(power);
            if x > bound {
                let (joint, _) = eig.eigenvectors.column(i).iter().enumerate().fold(
                    (0, 0.0),
                    |(bj, bv), (j, v)| if v.abs() > bv { (j, v.abs()) } else { (bj, bv) },
                );
                return Err(invalid(
                    field,
                    k.as_slice(),
                    &format!(
                    "gains at most {:.2e} times these: the arm's fastest mode (mostly joint {}) \
                     would make the servo unstable at its {:.0} Hz rate",
                    bound / x,
                    joint + 1,
                    1.0 / h
                ),
                ));
            }
        }
        Ok(())
    }
}

/// The arm's physics; every field is optional, the defaults give an ideal arm with a stiff
/// servo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RigidBodyConfig {
    /// Viscous friction per joint (N·m·s/rad); default none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub viscous: Option<Vec<f64>>,
    /// Coulomb friction per joint (N·m); default none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coulomb: Option<Vec<f64>>,
    /// The joint rate over which Coulomb friction reaches its level (rad/s, tanh).
    pub coulomb_width: f64,
    /// An unmodelled point mass at the tip (kg), at `payload_com` in the tip link's frame (m).
    pub payload: f64,
    pub payload_com: [f64; 3],
    /// Every link's mass and inertia, as a multiple of the description's.
    pub mass_scale: f64,
    /// Encoder step (rad); 0: exact positions.
    pub encoder_resolution: f64,
    /// Sensor noise, standard deviations: q (rad), q̇ (rad/s), τ (N·m).
    pub noise_q: f64,
    pub noise_qd: f64,
    pub noise_tau: f64,
    /// The noise generator's seed (the same seed gives the same run).
    pub seed: u64,
    /// The joint servo (position and velocity modes): each joint's natural frequency (Hz) and
    /// damping ratio on its inertia at the start, unless `servo_kp`/`servo_kd` give gains.
    pub servo_bandwidth_hz: f64,
    pub servo_damping: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub servo_kp: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub servo_kd: Option<Vec<f64>>,
}

impl Default for RigidBodyConfig {
    fn default() -> Self {
        Self {
            viscous: None,
            coulomb: None,
            coulomb_width: 0.02,
            payload: 0.0,
            payload_com: [0.0; 3],
            mass_scale: 1.0,
            encoder_resolution: 0.0,
            noise_q: 0.0,
            noise_qd: 0.0,
            noise_tau: 0.0,
            seed: 1,
            servo_bandwidth_hz: 50.0,
            servo_damping: 1.0,
            servo_kp: None,
            servo_kd: None,
        }
    }
}

/// A per-joint list, or `default` for every joint.
fn per_joint<const N: usize>(
    field: &str,
    v: &Option<Vec<f64>>,
    default: f64,
) -> Result<VecN<N>, ConfigError> {
    match v {
        None => Ok(VecN::<N>::repeat(default)),
        Some(v) if v.len() != N => Err(invalid(field, v, &format!("{N} numbers, one per joint"))),
        Some(v) if v.iter().all(|x| x.is_finite() && *x >= 0.0) => {
            Ok(VecN::<N>::from_column_slice(v))
        }
        Some(v) => Err(invalid(field, v, "finite numbers ≥ 0")),
    }
}

impl RigidBodyConfig {
    /// The simulated arm for `chain` starting at (q0, q̇0), its servo at step `h` (the plant's
    /// substep), torques clamped to `tau_max`. `prefix` names the table in errors
    /// (`plant.rigid_body`).
    pub fn build<const N: usize>(
        &self,
        chain: &Chain,
        start: (VecN<N>, VecN<N>),
        tau_max: VecN<N>,
        h: f64,
        prefix: &str,
    ) -> Result<(RigidBody<N>, Sensor<N>), ConfigError> {
        let f = |name: &str| format!("{prefix}.{name}");
        let scalars = [
            ("coulomb_width", self.coulomb_width, true),
            ("payload", self.payload, false),
            ("mass_scale", self.mass_scale, true),
            ("encoder_resolution", self.encoder_resolution, false),
            ("noise_q", self.noise_q, false),
            ("noise_qd", self.noise_qd, false),
            ("noise_tau", self.noise_tau, false),
            ("servo_bandwidth_hz", self.servo_bandwidth_hz, true),
            ("servo_damping", self.servo_damping, false),
        ];
        for (name, v, positive) in scalars {
            if !(v.is_finite() && (v > 0.0 || (!positive && v == 0.0))) {
                let want = if positive {
                    "a number > 0"
                } else {
                    "a number ≥ 0"
                };
                return Err(invalid(&f(name), v, want));
            }
        }
        if !self.payload_com.iter().all(|v| v.is_finite()) {
            return Err(invalid(
                &f("payload_com"),
                self.payload_com,
                "3 finite numbers",
            ));
        }
        let described: Model<N> = chain
            .model::<N>()
            .map_err(|e| invalid("robot.description", &chain.robot, &e.to_string()))?;
        if let Some(e) =
            chain.massless_joint(", or run the kinematic plant (plant.dynamics = \"kinematic\")")
        {
            return Err(e.into());
        }
        let model = mismatched(&described, self.payload, self.payload_com, self.mass_scale);
        if let Some(e) = chain.gravity_beyond_effort(&model, &start.0, &tau_max, "") {
            return Err(e.into());
        }
        let ms = inertias(&model, chain, &start.0);
        let auto = ServoGains::from_bandwidth(&ms, self.servo_bandwidth_hz, self.servo_damping);
        let servo = ServoGains {
            kp: match &self.servo_kp {
                Some(_) => per_joint::<N>(&f("servo_kp"), &self.servo_kp, 0.0)?,
                None => auto.kp,
            },
            kd: match &self.servo_kd {
                Some(_) => per_joint::<N>(&f("servo_kd"), &self.servo_kd, 0.0)?,
                None => auto.kd,
            },
        };
        let gains_field = if self.servo_kp.is_some() {
            "servo_kp"
        } else {
            "servo_bandwidth_hz"
        };
        let damping_field = if self.servo_kd.is_some() {
            "servo_kd"
        } else {
            "servo_bandwidth_hz"
        };
        if self.servo_kp.is_none() && self.servo_kd.is_none() {
            ServoGains::check_bandwidth(
                &ms,
                self.servo_bandwidth_hz,
                self.servo_damping,
                h,
                &f("servo_bandwidth_hz"),
            )?;
        } else {
            servo.check(&ms, h, &f(gains_field), &f(damping_field))?;
        }
        let arm = RigidBody::new(model, start.0, start.1, tau_max)
            .with_friction(
                per_joint::<N>(&f("viscous"), &self.viscous, 0.0)?,
                per_joint::<N>(&f("coulomb"), &self.coulomb, 0.0)?,
                self.coulomb_width,
            )
            .with_servo(servo);
        let noise = [self.noise_q, self.noise_qd, self.noise_tau];
        Ok((arm, Sensor::new(self.encoder_resolution, noise, self.seed)))
    }
}

/// How many postures besides the start [`inertias`] samples.
pub const POSTURES: usize = 64;

/// The arm's inertia at the start `q0` and at [`POSTURES`] postures spread over the joints'
/// ranges (a fixed low-discrepancy sequence: the same set every time), for the gain rules
/// above. Start-up only.
pub fn inertias<const N: usize>(model: &Model<N>, chain: &Chain, q0: &VecN<N>) -> Vec<Inertia<N>> {
    // Additive recurrence with the generalised golden ratio for N dimensions (R_N sequence).
    let mut phi = 2.0f64;
    for _ in 0..32 {
        phi = (1.0 + phi).powf(1.0 / (N as f64 + 1.0));
    }
    let alpha: Vec<f64> = (1..=N)
        .map(|i| (1.0 / phi.powi(i as i32)).fract())
        .collect();
    let mut out = vec![model.mass_matrix(q0)];
    for k in 1..=POSTURES {
        let q = VecN::<N>::from_fn(|i, _| {
            let l = &chain.joints[i].limits;
            let (lo, hi) = if l.lower.is_finite() && l.upper.is_finite() {
                (l.lower, l.upper)
            } else {
                (-std::f64::consts::PI, std::f64::consts::PI)
            };
            lo + (hi - lo) * (0.5 + alpha[i] * k as f64).fract()
        });
        out.push(model.mass_matrix(&q));
    }
    out
}
