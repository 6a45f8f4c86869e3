//! A secondary task of your own: keep a redundant arm near a preferred posture while its hand
//! tracks the path. The law adds α(I − J⁺J)η to the joint accelerations, so η may pull the
//! posture anywhere; the projection keeps the hand on its path.
//!
//! A task is a type that implements [`NullTask`]: given the state (and the tool point and its
//! Jacobian, unused here), write η and return the task's value. It is called on every tick of
//! the real-time loop, so it must not allocate, lock or block.

use control::secondary::custom::NullTask;
use control::secondary::custom::NullTaskInput;

/// The posture task: cost ½k‖q − q_ref‖², η = −k(q − q_ref), the cost's descent direction.
pub struct Posture {
    /// The preferred joint angles (rad), one per joint; joints beyond them are left free.
    pub q_ref: &'static [f64],
    /// The pull (1/s² once the law's α multiplies it).
    pub k: f64,
}

impl NullTask for Posture {
    fn eta(&self, x: &NullTaskInput, eta: &mut [f64]) -> f64 {
        let mut cost = 0.0;
        for (i, (q, q_ref)) in x.q.iter().zip(self.q_ref).enumerate() {
            let e = q - q_ref;
            eta[i] = -self.k * e;
            cost += 0.5 * self.k * e * e;
        }
        cost
    }
}

/// The Franka Panda's "ready" posture, the one its tools start from.
pub static PANDA_READY: Posture = Posture {
    q_ref: &[0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785],
    k: 1.0,
};

/// The name a config gives in `law.secondary`.
pub const NAME: &str = "ready-posture";
