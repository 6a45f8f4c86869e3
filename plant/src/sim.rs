//! The simulated arm behind the Plant seam.
//!
//! It integrates the same kinematic plant as the offline simulation (`control::sim`): the
//! commanded q̈ is the joint acceleration, and for the floating base φ̇ = −H_b⁻¹H_bm q̇. The
//! command is ramped over the period (`control::hold`: q̈ + q⃛·s from the answered state, a
//! first-order hold; q⃛ = 0 gives a zero-order hold) and integrated with RK4 in substeps.

use crate::seam::{Actuation, Plant, PlantError};
use control::hold;
use control::sim::{plant_derivative, rk4_step};
use control::{ArmModel, ArmState, VecN};
use protocol::{flags, StateSample};

pub struct SimPlant<const N: usize> {
    model: ArmModel<N>,
    state: ArmState<N>,
    substeps: u32,
    brake_gain: f64,
    qdd: VecN<N>,
    qddd: VecN<N>,
    since: f64,
    braking: bool,
}

/// How far past the expected hold interval a ramp may run (periods) before it is held constant.
const MAX_RAMP_PERIODS: f64 = 3.0;

impl<const N: usize> SimPlant<N> {
    pub fn new(model: ArmModel<N>, initial: ArmState<N>, substeps: u32, brake_gain: f64) -> Self {
        Self {
            model,
            state: initial,
            substeps: substeps.max(1),
            brake_gain,
            qdd: VecN::<N>::zeros(),
            qddd: VecN::<N>::zeros(),
            since: 0.0,
            braking: true,
        }
    }

    pub fn state(&self) -> &ArmState<N> {
        &self.state
    }

    fn base_rate(&self, x: &ArmState<N>) -> f64 {
        match &self.model {
            ArmModel::Fixed(_) => 0.0,
            ArmModel::Floating(a) => a.base_rate(&x.q, &x.qd),
        }
    }
}

impl<const N: usize> Plant for SimPlant<N> {
    fn n(&self) -> usize {
        N
    }

    fn flags(&self) -> u32 {
        let mut f = flags::SIMULATED;
        if self.model.is_floating() {
            f |= flags::FLOATING_BASE;
        }
        if self.braking {
            f |= flags::BRAKING;
        }
        f
    }

    fn activate(&mut self) -> Result<(), PlantError> {
        Ok(())
    }

    fn write(&mut self, actuation: Actuation<'_>) {
        match actuation {
            Actuation::Accelerate { qdd, qddd, since }
                if qdd.len() == N && qddd.len() == N && since.is_finite() =>
            {
                self.qdd = VecN::<N>::from_column_slice(qdd);
                self.qddd = VecN::<N>::from_column_slice(qddd);
                self.since = since.max(0.0);
                self.braking = false;
            }
            _ => self.braking = true,
        }
    }

    fn read(&mut self, dt: f64, out: &mut StateSample) -> Result<(), PlantError> {
        if dt > 0.0 {
            if self.braking {
                let h = dt / self.substeps as f64;
                for _ in 0..self.substeps {
                    let gain = self.brake_gain;
                    self.state = rk4_step(&self.state, h, |_, x| {
                        plant_derivative(x, &(-x.qd * gain), self.base_rate(x))
                    });
                }
            } else {
                let max_ramp = MAX_RAMP_PERIODS * dt;
                self.state = hold::integrate(
                    &self.model,
                    &self.state,
                    &self.qdd,
                    &self.qddd,
                    self.since,
                    max_ramp,
                    dt,
                    self.substeps,
                );
                self.since += dt;
            }
        }
        if !self.state.is_finite() {
            return Err(PlantError::Fault(
                "the simulated state became non-finite".into(),
            ));
        }
        out.n = N as u32;
        out.phi = self.state.phi;
        out.q[..N].copy_from_slice(self.state.q.as_slice());
        out.qd[..N].copy_from_slice(self.state.qd.as_slice());
        Ok(())
    }

    fn deactivate(&mut self) {
        self.braking = true;
    }

    fn stamp(&self, nominal_ns: u64, _now_ns: u64) -> u64 {
        nominal_ns
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
        let mut p = SimPlant::new(cfg.model::<3>(), x0, 4, 20.0);
        let mut s = StateSample::default();
        // Constant acceleration for 0.1 s: q̇ grows by exactly a·t.
        p.write(Actuation::Accelerate {
            qdd: &[1.0, 0.0, -1.0],
            qddd: &[0.0; 3],
            since: 0.0,
        });
        for _ in 0..100 {
            p.read(1e-3, &mut s).unwrap();
        }
        assert!(
            (s.qd[0] - 1.1).abs() < 1e-12 && (s.qd[2] - 0.4).abs() < 1e-12,
            "{:?}",
            s.qd
        );
        assert_eq!(p.flags() & flags::BRAKING, 0);
        p.write(Actuation::Brake);
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
        });
        assert_ne!(p.flags() & flags::BRAKING, 0);
    }
}
