//! The simulated arm behind the Plant seam.
//!
//! It integrates the same kinematic plant as the offline simulation (`control::sim`): the
//! commanded q̈ is the joint acceleration, and for the floating base φ̇ = −H_b⁻¹H_bm q̇. The
//! command is ramped over the period (`control::hold`: q̈ + q⃛·s from the answered state, a
//! first-order hold; q⃛ = 0 gives a zero-order hold) and integrated with RK4 in substeps.
//!
//! Physics does not pause: after a stall the loop passes the whole elapsed time to one `read`,
//! and the simulator integrates it period by period, so the state stays on the time its stamp
//! claims. A long stall (SIGSTOP, a paused VM) is not replayed: at most [`MAX_CATCH_UP_S`] is
//! integrated in one `read`, the rest is skipped and counted ([`SimPlant::time_jumps`]). That
//! bound lives here, not in the loop, because only a simulator has time to catch up.

use crate::config::{Dynamics, PlantConfig};
use crate::seam::{Actuation, Plant, PlantError};
use control::command::Command;
use control::command::CommandMode;
use control::hold;
use control::rigid_body::Device;
use control::sim::{plant_derivative, rk4_step};
use control::{ArmModel, ArmState, ConfigError, System, VecN};
use protocol::{flags, StateSample};

/// How the arm moves between two reads.
enum Physics<const N: usize> {
    /// The command is the motion: q̈ integrated, or a position (velocity) reached exactly.
    Kinematic(ArmModel<N>),
    /// The rigid-body arm: a device with dynamics, servo and sensors.
    RigidBody(Box<Device<N>>),
}

/// What a kinematic arm follows.
#[derive(Clone, Copy)]
enum Follow<const N: usize> {
    Ramp,
    Position { q: VecN<N>, qd: VecN<N> },
    Velocity(VecN<N>),
}

pub struct SimPlant<const N: usize> {
    physics: Physics<N>,
    state: ArmState<N>,
    substeps: u32,
    brake_gain: f64,
    qdd: VecN<N>,
    qddd: VecN<N>,
    follow: Follow<N>,
    since: f64,
    braking: bool,
    period: f64,
    time_jumps: u64,
    /// The torques the arm applied over the last substep (rigid body; zeros otherwise).
    tau: VecN<N>,
}

/// The most simulated time one `read` integrates after a stall (s).
pub const MAX_CATCH_UP_S: f64 = 1.0;

/// How far past the expected hold interval a ramp may run (periods) before it is held constant.
const MAX_RAMP_PERIODS: f64 = 3.0;

impl<const N: usize> SimPlant<N> {
    /// A kinematic arm integrating `period` seconds per cycle in `substeps` RK4 steps.
    pub fn new(
        model: ArmModel<N>,
        initial: ArmState<N>,
        period: f64,
        substeps: u32,
        brake_gain: f64,
    ) -> Self {
        Self {
            period,
            time_jumps: 0,
            physics: Physics::Kinematic(model),
            state: initial,
            substeps: substeps.max(1),
            brake_gain,
            qdd: VecN::<N>::zeros(),
            qddd: VecN::<N>::zeros(),
            follow: Follow::Ramp,
            since: 0.0,
            braking: true,
            tau: VecN::<N>::zeros(),
        }
    }

    /// The kinematic arm a config describes: the planar arm's model (a floating base turns), or
    /// a URDF chain on its fixed base. `N` must be `system.n()`.
    pub fn for_system(system: &System, period: f64, substeps: u32, brake_gain: f64) -> Self {
        Self::new(
            system.kinematic_model::<N>(),
            system.initial_state(),
            period,
            substeps,
            brake_gain,
        )
    }

    /// The arm `[plant]` asks for: kinematic, or the rigid-body arm of `[plant.rigid_body]`.
    /// Refuses, naming the field, a combination that cannot run (torque commands to a
    /// kinematic arm, rigid-body dynamics without a robot model).
    pub fn from_config(system: &System, cfg: &PlantConfig) -> Result<Self, ConfigError> {
        let period = cfg.period_ns() as f64 * 1e-9;
        let mut sim = Self::for_system(system, period, cfg.substeps, cfg.brake_gain);
        let mode = system.command_mode();
        match (cfg.dynamics, system.robot()) {
            (Dynamics::Kinematic, _) if mode == CommandMode::Torque => Err(ConfigError::Invalid {
                field: "plant.dynamics".into(),
                value: "\"kinematic\"".into(),
                expected: "\"rigid-body\" with command.mode = \"torque\": a kinematic arm has no \
                           masses to apply torques to"
                    .into(),
            }),
            (Dynamics::Kinematic, _) => Ok(sim),
            (Dynamics::Mujoco, _) => Err(ConfigError::Invalid {
                field: "plant.dynamics".into(),
                value: "\"mujoco\"".into(),
                expected: "a program built with MuJoCo: chaosd-plant-mujoco (docs/mujoco.md); \
                           chaosd-plant hands such a set-up over to it when it is installed"
                    .into(),
            }),
            (Dynamics::RigidBody, None) => Err(ConfigError::Invalid {
                field: "plant.dynamics".into(),
                value: "\"rigid-body\"".into(),
                expected: "\"kinematic\" for the paper's planar arm, which has no mass model; \
                           name a robot in [robot] for rigid-body dynamics"
                    .into(),
            }),
            (Dynamics::RigidBody, Some(s)) => {
                let x = sim.state;
                let limits = s
                    .own()
                    .command
                    .limits::<N>(&s.chain, &s.own().robot.description)?;
                let tau_max = VecN::<N>::from_column_slice(&limits.tau);
                let h = period / f64::from(sim.substeps);
                let (arm, sensor) = cfg.rigid_body.build::<N>(
                    &s.chain,
                    (x.q, x.qd),
                    tau_max,
                    h,
                    "plant.rigid_body",
                )?;
                sim.physics = Physics::RigidBody(Box::new(Device::new(arm, sensor)));
                Ok(sim)
            }
        }
    }

    /// The same arm, at rest: a device powers up standing still, whatever the set-up's q̇0
    /// (which seeds the law's self-motion in a simulation, not a real arm's).
    pub fn at_rest(mut self) -> Self {
        self.state.qd = VecN::<N>::zeros();
        if let Physics::RigidBody(d) = &mut self.physics {
            d.arm.state.qd = VecN::<N>::zeros();
        }
        self
    }

    pub fn state(&self) -> &ArmState<N> {
        &self.state
    }

    /// Stalls longer than [`MAX_CATCH_UP_S`], whose excess time was skipped, not simulated.
    pub fn time_jumps(&self) -> u64 {
        self.time_jumps
    }

    /// Integrates one period of `dt` with the current actuation.
    fn step(&mut self, dt: f64) {
        if let Physics::RigidBody(d) = &mut self.physics {
            d.advance(dt, self.substeps);
            let m = d.measure();
            (self.state.q, self.state.qd, self.tau) = (m.q, m.qd, m.tau);
            return;
        }
        if self.braking {
            let h = dt / self.substeps as f64;
            for _ in 0..self.substeps {
                let gain = self.brake_gain;
                self.state = rk4_step(&self.state, h, |_, x| {
                    plant_derivative(x, &(-x.qd * gain), self.base_rate(x))
                });
            }
            return;
        }
        match self.follow {
            Follow::Ramp => {
                let Physics::Kinematic(model) = &self.physics else {
                    return;
                };
                let max_ramp = MAX_RAMP_PERIODS * dt;
                self.state = hold::integrate(
                    model,
                    &self.state,
                    &self.qdd,
                    &self.qddd,
                    self.since,
                    max_ramp,
                    dt,
                    self.substeps,
                );
            }
            // An ideal servo: the reference is the motion (it moves on at its rate if late).
            Follow::Position { q, qd } => {
                self.state.q = q + qd * (self.since + dt - self.period).max(0.0);
                self.state.qd = qd;
            }
            Follow::Velocity(qd) => {
                self.state.q += qd * dt;
                self.state.qd = qd;
            }
        }
        self.since += dt;
    }

    fn base_rate(&self, x: &ArmState<N>) -> f64 {
        match &self.physics {
            Physics::Kinematic(ArmModel::Floating(a)) => a.base_rate(&x.q, &x.qd),
            _ => 0.0,
        }
    }

    /// Hands a command to the rigid-body device.
    fn drive(&mut self, mode: CommandMode, fill: impl FnOnce(&mut Command<N>), since: f64) {
        if let Physics::RigidBody(d) = &mut self.physics {
            let mut c = Command::still(mode);
            fill(&mut c);
            d.command(&c, self.period, since);
        }
    }
}

/// Whether every slice has the arm's length and `since` is a time.
fn fits<const N: usize>(slices: &[&[f64]], since: f64) -> bool {
    slices.iter().all(|s| s.len() == N) && since.is_finite()
}

impl<const N: usize> Plant for SimPlant<N> {
    fn n(&self) -> usize {
        N
    }

    fn flags(&self) -> u32 {
        let mut f = flags::SIMULATED;
        if let Physics::Kinematic(m) = &self.physics {
            if m.is_floating() {
                f |= flags::FLOATING_BASE;
            }
        }
        if self.braking {
            f |= flags::BRAKING;
        }
        f
    }

    fn activate(&mut self) -> Result<(), PlantError> {
        Ok(())
    }

    fn write(&mut self, actuation: Actuation<'_>) -> Result<(), PlantError> {
        let v = VecN::<N>::from_column_slice;
        self.braking = false;
        match actuation {
            Actuation::Accelerate {
                qdd, qddd, since, ..
            } if fits::<N>(&[qdd, qddd], since) => {
                self.qdd = v(qdd);
                self.qddd = v(qddd);
                self.follow = Follow::Ramp;
                self.since = since.max(0.0);
                let (a, r) = (self.qdd, self.qddd);
                self.drive(
                    CommandMode::Acceleration,
                    |c| (c.qdd, c.qddd) = (a, r),
                    since,
                );
            }
            Actuation::Position { q, qd, since, .. } if fits::<N>(&[q, qd], since) => {
                let (q, qd) = (v(q), v(qd));
                self.follow = Follow::Position { q, qd };
                self.since = since.max(0.0);
                self.drive(CommandMode::Position, |c| (c.q, c.qd) = (q, qd), since);
            }
            Actuation::Velocity { qd, since, .. } if fits::<N>(&[qd], since) => {
                let qd = v(qd);
                self.follow = Follow::Velocity(qd);
                self.since = since.max(0.0);
                self.drive(CommandMode::Velocity, |c| c.qd = qd, since);
            }
            Actuation::Torque { tau, since, .. }
                if fits::<N>(&[tau], since) && matches!(self.physics, Physics::RigidBody(_)) =>
            {
                let tau = v(tau);
                self.drive(CommandMode::Torque, |c| c.tau = tau, since);
            }
            // Hold, Brake, and anything malformed come to rest: a simulated arm has no brakes
            // to engage (the rigid-body arm holds with its servo).
            _ => {
                self.braking = true;
                if let Physics::RigidBody(d) = &mut self.physics {
                    d.hold();
                }
            }
        }
        Ok(())
    }

    fn read(&mut self, elapsed: f64, out: &mut StateSample) -> Result<(), PlantError> {
        if elapsed > 0.0 && elapsed.is_finite() {
            let mut left = elapsed;
            if left > MAX_CATCH_UP_S + self.period {
                self.time_jumps += 1;
                left = MAX_CATCH_UP_S;
            }
            // The loop passes whole periods; integrate them one by one, as single reads would.
            let periods = (left / self.period).round().max(1.0) as u64;
            for _ in 0..periods {
                self.step(self.period);
            }
        }
        if !self.state.is_finite() {
            return Err(PlantError::Fault {
                what: "the simulated state became non-finite",
                source: None,
            });
        }
        out.n = N as u32;
        out.phi = self.state.phi;
        out.q[..N].copy_from_slice(self.state.q.as_slice());
        out.qd[..N].copy_from_slice(self.state.qd.as_slice());
        out.tau[..N].copy_from_slice(self.tau.as_slice());
        Ok(())
    }

    fn deactivate(&mut self) {
        self.braking = true;
    }

    fn stamp(&self, nominal_ns: u64, _now_ns: u64) -> u64 {
        nominal_ns
    }

    fn effort_clamps(&self) -> u64 {
        match &self.physics {
            Physics::RigidBody(d) => d.arm.torque_saturations,
            Physics::Kinematic(_) => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::Config;

    #[test]
    fn integrates_commands_and_brakes_to_rest() {
        let cfg = Config::preset("paper").unwrap();
        let mut x0: ArmState<3> = cfg.initial_state();
        x0.qd = VecN::<3>::new(1.0, -2.0, 0.5);
        let mut p = SimPlant::new(cfg.model::<3>(), x0, 1e-3, 4, 20.0);
        let mut s = StateSample::default();
        // Constant acceleration for 0.1 s: q̇ grows by exactly a·t.
        p.write(Actuation::Accelerate {
            qdd: &[1.0, 0.0, -1.0],
            qddd: &[0.0; 3],
            since: 0.0,
            answers: 0,
        })
        .unwrap();
        for _ in 0..100 {
            p.read(1e-3, &mut s).unwrap();
        }
        assert!(
            (s.qd[0] - 1.1).abs() < 1e-12 && (s.qd[2] - 0.4).abs() < 1e-12,
            "{:?}",
            s.qd
        );
        assert_eq!(p.flags() & flags::BRAKING, 0);
        p.write(Actuation::Brake).unwrap();
        for _ in 0..1000 {
            p.read(1e-3, &mut s).unwrap();
        }
        assert!(s.qd[..3].iter().all(|v| v.abs() < 1e-6), "{:?}", s.qd);
        assert_ne!(p.flags() & flags::BRAKING, 0);
        // A wrong-length command is not applied: the plant brakes instead.
        p.write(Actuation::Accelerate {
            qdd: &[1.0],
            qddd: &[0.0],
            since: 0.0,
            answers: 0,
        })
        .unwrap();
        assert_ne!(p.flags() & flags::BRAKING, 0);
    }

    #[test]
    fn a_stall_is_caught_up_in_one_read_and_a_long_one_is_bounded() {
        let cfg = Config::preset("paper").unwrap();
        let x0: ArmState<3> = cfg.initial_state();
        let accel = Actuation::Accelerate {
            qdd: &[1.0, 0.0, 0.0],
            qddd: &[0.0; 3],
            since: 0.0,
            answers: 0,
        };
        let mut s = StateSample::default();
        // Five periods in one read = five reads of one period, bit for bit.
        let mut a = SimPlant::new(cfg.model::<3>(), x0, 1e-3, 4, 20.0);
        let mut b = SimPlant::new(cfg.model::<3>(), x0, 1e-3, 4, 20.0);
        a.write(accel).unwrap();
        b.write(accel).unwrap();
        a.read(5e-3, &mut s).unwrap();
        for _ in 0..5 {
            b.read(1e-3, &mut s).unwrap();
        }
        assert_eq!(a.state().qd, b.state().qd);
        assert_eq!(a.time_jumps(), 0);
        // A 10 s stall integrates one second and counts the jump.
        let mut c = SimPlant::new(cfg.model::<3>(), x0, 1e-3, 4, 20.0);
        c.write(accel).unwrap();
        c.read(10.0, &mut s).unwrap();
        assert!((s.qd[0] - MAX_CATCH_UP_S).abs() < 1e-9, "{}", s.qd[0]);
        assert_eq!(c.time_jumps(), 1);
    }
}
