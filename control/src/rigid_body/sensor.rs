//! What the arm's sensors report: encoder counts and noisy rates and torques, reproducibly.

use super::Motion;
use crate::arm::VecN;

/// Encoder quantization and Gaussian noise, from a seeded generator (the same seed gives the
/// same run).
#[derive(Debug, Clone)]
pub struct Sensor<const N: usize> {
    /// Encoder step (rad); 0: exact.
    pub resolution: f64,
    /// Standard deviations of the noise on q (rad), q̇ (rad/s) and τ (N·m).
    pub noise_q: f64,
    pub noise_qd: f64,
    pub noise_tau: f64,
    rng: u64,
}

/// A measurement: what the state sample carries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured<const N: usize> {
    pub q: VecN<N>,
    pub qd: VecN<N>,
    pub tau: VecN<N>,
}

impl<const N: usize> Sensor<N> {
    pub fn new(resolution: f64, noise: [f64; 3], seed: u64) -> Self {
        Self {
            resolution,
            noise_q: noise[0],
            noise_qd: noise[1],
            noise_tau: noise[2],
            // xorshift must not start at 0.
            rng: seed ^ 0x9E37_79B9_7F4A_7C15,
        }
    }

    /// An exact sensor.
    pub fn exact() -> Self {
        Self::new(0.0, [0.0; 3], 1)
    }

    /// Measures the true motion `x` and applied torque `tau`.
    pub fn measure(&mut self, x: &Motion<N>, tau: &VecN<N>) -> Measured<N> {
        let mut m = Measured {
            q: x.q,
            qd: x.qd,
            tau: *tau,
        };
        for i in 0..N {
            m.q[i] += self.noise(self.noise_q);
            if self.resolution > 0.0 {
                m.q[i] = (m.q[i] / self.resolution).round() * self.resolution;
            }
            m.qd[i] += self.noise(self.noise_qd);
            m.tau[i] += self.noise(self.noise_tau);
        }
        m
    }

    /// A normal sample of standard deviation `sigma` (0 draws nothing).
    fn noise(&mut self, sigma: f64) -> f64 {
        if sigma <= 0.0 {
            return 0.0;
        }
        let u1 = self.uniform().max(f64::MIN_POSITIVE);
        let u2 = self.uniform();
        sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// xorshift64*: a uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let x = self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (x >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_seeded_and_has_its_spread_and_encoders_quantize() {
        let x = Motion {
            q: VecN::<2>::new(0.123456, -1.0),
            qd: VecN::<2>::zeros(),
        };
        let mut a = Sensor::<2>::new(1e-3, [0.0, 0.01, 0.0], 7);
        let mut b = Sensor::<2>::new(1e-3, [0.0, 0.01, 0.0], 7);
        let t = VecN::<2>::zeros();
        let ma = a.measure(&x, &t);
        assert_eq!(ma, b.measure(&x, &t));
        assert!((ma.q[0] - 0.123).abs() < 1e-12);
        let n = 20000;
        let var: f64 = (0..n).map(|_| a.measure(&x, &t).qd[0].powi(2)).sum::<f64>() / n as f64;
        assert!((var.sqrt() - 0.01).abs() < 5e-4, "{}", var.sqrt());
        assert_eq!(Sensor::<2>::exact().measure(&x, &t).q, x.q);
    }
}
