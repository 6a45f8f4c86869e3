//! An arm with mass: the plant that integrates the rigid-body dynamics instead of q̈ directly.
//!
//! The kinematic plant makes every command exact, so it cannot tell a torque from an
//! acceleration, nor show what a payload, friction or a servo's lag does. This one integrates
//! M(q)q̈ + C(q,q̇)q̇ + g(q) = τ − friction(q̇) by the articulated-body algorithm, with the torque
//! clamped to the arm's limits, and measures like a robot: encoder quantization, seeded sensor
//! noise, and the torque it applied. Its model may differ from the controller's (a payload at
//! the tip, a scale on the link masses), so a controller can be tested against the arm it does
//! not know exactly.
//!
//! Position and velocity commands are followed by the arm's own joint servo (PD plus gravity
//! compensation, as the robot's controller does); torque is applied as sent; an acceleration is
//! turned into torque by the arm's own inverse dynamics. The actuation is recomputed every
//! substep (the servo runs at the substep rate) and held over the substep's RK4 step.

mod config;
mod device;
mod sensor;

pub use config::{inertias, Inertia, RigidBodyConfig, ServoGains, POSTURES};
pub use device::Device;
pub use sensor::{Measured, Sensor};

use crate::arm::VecN;
use crate::model::{Body, Model};
use crate::sim::{rk4_step, OdeState};

/// What the arm is asked to do until the next command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drive<const N: usize> {
    /// Joint torques (N·m), as sent.
    Torque(VecN<N>),
    /// Follow the reference (q, q̇) with the joint servo; the reference moves on at q̇ (and q̈)
    /// between commands, as the robot interpolates its set-point.
    Track {
        q: VecN<N>,
        qd: VecN<N>,
        qdd: VecN<N>,
    },
    /// Follow q̈ by the arm's own inverse dynamics.
    Accelerate(VecN<N>),
    /// Follow the ramp q̈ + q⃛·s (s from the drive's start) by the arm's own inverse dynamics.
    Ramp { qdd: VecN<N>, qddd: VecN<N> },
    /// Come to rest: the servo holds the position reached, with damping.
    Hold,
}

/// The state the RK4 integrates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion<const N: usize> {
    pub q: VecN<N>,
    pub qd: VecN<N>,
}

impl<const N: usize> OdeState for Motion<N> {
    #[inline(always)]
    fn add_scaled(&self, k: &Self, h: f64) -> Self {
        Self {
            q: self.q + k.q * h,
            qd: self.qd + k.qd * h,
        }
    }
}

/// The simulated arm.
#[derive(Debug, Clone)]
pub struct RigidBody<const N: usize> {
    /// The true arm (with its payload and mass errors).
    model: Model<N>,
    viscous: VecN<N>,
    coulomb: VecN<N>,
    coulomb_width: f64,
    tau_max: VecN<N>,
    servo: ServoGains<N>,
    pub state: Motion<N>,
    /// The torque applied over the last substep (after the limits).
    pub applied: VecN<N>,
    /// Where a Hold keeps the joints.
    hold_at: Option<VecN<N>>,
    /// Substeps in which a torque was clamped to its limit while following a command.
    pub torque_saturations: u64,
    /// Substeps in which it was clamped while braking to rest ([`Drive::Hold`]): a brake
    /// stops the arm with all the torque it has, so these are the brake at work, not a
    /// command the arm could not follow.
    pub brake_saturations: u64,
}

impl<const N: usize> RigidBody<N> {
    /// `model` is the true arm; `tau_max` clamps every applied torque (∞: no limit).
    pub fn new(model: Model<N>, q: VecN<N>, qd: VecN<N>, tau_max: VecN<N>) -> Self {
        Self {
            model,
            viscous: VecN::<N>::zeros(),
            coulomb: VecN::<N>::zeros(),
            coulomb_width: 0.02,
            tau_max,
            servo: ServoGains {
                kp: VecN::<N>::zeros(),
                kd: VecN::<N>::zeros(),
            },
            state: Motion { q, qd },
            applied: VecN::<N>::zeros(),
            hold_at: None,
            torque_saturations: 0,
            brake_saturations: 0,
        }
    }

    /// Viscous (N·m·s/rad) and Coulomb (N·m) friction per joint; the Coulomb term is smoothed
    /// over `width` rad/s (tanh) so the integrator sees no step.
    pub fn with_friction(mut self, viscous: VecN<N>, coulomb: VecN<N>, width: f64) -> Self {
        self.viscous = viscous;
        self.coulomb = coulomb;
        self.coulomb_width = width.max(1e-9);
        self
    }

    pub fn with_servo(mut self, servo: ServoGains<N>) -> Self {
        self.servo = servo;
        self
    }

    pub fn model(&self) -> &Model<N> {
        &self.model
    }

    /// Friction torque at joint rates `qd` (opposes the motion).
    pub fn friction(&self, qd: &VecN<N>) -> VecN<N> {
        VecN::<N>::from_fn(|i, _| {
            self.viscous[i] * qd[i] + self.coulomb[i] * (qd[i] / self.coulomb_width).tanh()
        })
    }

    /// Kinetic energy ½ q̇ᵀ M(q) q̇ (J).
    pub fn kinetic_energy(&self) -> f64 {
        let m = self.model.mass_matrix(&self.state.q);
        0.5 * self.state.qd.dot(&(m * self.state.qd))
    }

    /// Advances `h` seconds in `substeps` RK4 steps under `drive`, which began `since` seconds
    /// ago (a tracked reference has moved on by then).
    pub fn advance(&mut self, drive: &Drive<N>, since: f64, h: f64, substeps: u32) {
        let k = h / f64::from(substeps.max(1));
        for s in 0..substeps.max(1) {
            let tau = self.actuation(drive, since + k * f64::from(s));
            self.applied = tau;
            let model = &self.model;
            let this = &*self;
            self.state = rk4_step(&self.state, k, |_, x| Motion {
                q: x.qd,
                qd: model.aba(&x.q, &x.qd, &(tau - this.friction(&x.qd))),
            });
        }
    }

    /// The torque the arm applies at this instant, clamped to its limits.
    fn actuation(&mut self, drive: &Drive<N>, since: f64) -> VecN<N> {
        let Motion { q, qd } = self.state;
        let wanted = match drive {
            Drive::Torque(t) => *t,
            Drive::Accelerate(a) => self.model.rnea(&q, &qd, a) + self.friction(&qd),
            Drive::Ramp { qdd, qddd } => {
                let a = qdd + qddd * since.max(0.0);
                self.model.rnea(&q, &qd, &a) + self.friction(&qd)
            }
            Drive::Track {
                q: qr,
                qd: qdr,
                qdd,
            } => {
                let at = qr + qdr * since + qdd * (0.5 * since * since);
                let rate = qdr + qdd * since;
                self.servo_torque(&at, &rate)
            }
            Drive::Hold => {
                let at = *self.hold_at.get_or_insert(q);
                self.servo_torque(&at, &VecN::<N>::zeros())
            }
        };
        if !matches!(drive, Drive::Hold) {
            self.hold_at = None;
        }
        let clamped = VecN::<N>::from_fn(|i, _| wanted[i].clamp(-self.tau_max[i], self.tau_max[i]));
        if clamped != wanted {
            match drive {
                Drive::Hold => self.brake_saturations += 1,
                _ => self.torque_saturations += 1,
            }
        }
        clamped
    }

    /// PD on the reference plus gravity compensation: the robot's joint servo.
    fn servo_torque(&self, at: &VecN<N>, rate: &VecN<N>) -> VecN<N> {
        let Motion { q, qd } = self.state;
        self.model.gravity_torques(&q)
            + self.servo.kp.component_mul(&(at - q))
            + self.servo.kd.component_mul(&(rate - qd))
    }
}

/// A model with a point payload at `com` (in the tip link's frame) and every link's mass and
/// inertia scaled by `mass_scale`: the arm as it really is, when the controller's model is not.
pub fn mismatched<const N: usize>(
    model: &Model<N>,
    payload: f64,
    com: [f64; 3],
    mass_scale: f64,
) -> Model<N> {
    let mut m = *model;
    for b in &mut m.body {
        b.mass *= mass_scale;
        b.inertia *= mass_scale;
    }
    if payload > 0.0 && N > 0 {
        let point = Body {
            mass: payload,
            com: m.tip.apply(&nalgebra::Vector3::from(com)),
            inertia: nalgebra::Matrix3::zeros(),
        };
        m.body[N - 1] = m.body[N - 1].merged(&point);
    }
    m
}
