//! min ½|δ|² subject to a_k·δ ≥ h_k by Goldfarb and Idnani's dual active-set method
//! (Math. Programming 27, 1983), for the identity Hessian.
//!
//! Hildreth's coordinate ascent ([`super::solve`]) needs no factorisation but crawls when the
//! rows are nearly dependent, which is the rule, not the exception, once a 7-joint arm's joint
//! box is projected onto a 4-dimensional null space: hundreds of sweeps and a wrong "infeasible".
//! The dual method adds the most violated row, moves along the projection of its normal onto
//! the complement of the active rows, and drops a row whose multiplier would turn negative; it
//! ends in a few steps with the exact minimiser or a proof that none exists. The active set
//! never holds more than n independent rows, so its Gram matrix is at most n×n, on the stack.

use crate::arm::VecN;

/// A row counts as met when it misses by at most this (relative to 1 + |h|).
const TOL: f64 = 1e-9;

/// The active rows and their multipliers.
struct Active<const N: usize> {
    idx: [usize; N],
    u: [f64; N],
    q: usize,
}

impl<const N: usize> Active<N> {
    fn drop(&mut self, l: usize) {
        for i in l..self.q - 1 {
            self.idx[i] = self.idx[i + 1];
            self.u[i] = self.u[i + 1];
        }
        self.q -= 1;
    }

    /// r = (NᵀN)⁻¹Nᵀv and z = v − N r for N = the active rows as columns; None if they are
    /// dependent (the Gram matrix is not positive definite).
    fn split(&self, a: &[VecN<N>], v: &VecN<N>) -> Option<([f64; N], VecN<N>)> {
        let q = self.q;
        let mut g = [[0.0f64; N]; N];
        let mut r = [0.0f64; N];
        for i in 0..q {
            for j in 0..=i {
                g[i][j] = a[self.idx[i]].dot(&a[self.idx[j]]);
            }
            r[i] = a[self.idx[i]].dot(v);
        }
        // Cholesky G = LLᵀ in place (lower triangle), then two triangular solves.
        for i in 0..q {
            for j in 0..=i {
                let mut s = g[i][j];
                for k in 0..j {
                    s -= g[i][k] * g[j][k];
                }
                if i == j {
                    if s <= 1e-14 * (1.0 + g[i][i].abs()) {
                        return None;
                    }
                    g[i][i] = s.sqrt();
                } else {
                    g[i][j] = s / g[j][j];
                }
            }
        }
        for i in 0..q {
            let mut s = r[i];
            for k in 0..i {
                s -= g[i][k] * r[k];
            }
            r[i] = s / g[i][i];
        }
        for i in (0..q).rev() {
            let mut s = r[i];
            for k in i + 1..q {
                s -= g[k][i] * r[k];
            }
            r[i] = s / g[i][i];
        }
        let mut z = *v;
        for i in 0..q {
            z -= a[self.idx[i]] * r[i];
        }
        Some((r, z))
    }
}

/// What the method found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome<const N: usize> {
    /// The exact minimiser.
    Solved(VecN<N>),
    /// No δ meets every row (a violated row lies in the span of active rows whose multipliers
    /// cannot move: Goldfarb and Idnani's infeasibility certificate).
    Infeasible,
    /// A case it does not resolve (dependent active rows, or the step budget ran out): the
    /// caller falls back to Hildreth's method.
    Undecided,
}

/// Solves the problem; see [`Outcome`].
pub fn solve<const N: usize>(a: &[VecN<N>], h: &[f64]) -> Outcome<N> {
    let mut x = VecN::<N>::zeros();
    let mut act = Active::<N> {
        idx: [0; N],
        u: [0.0; N],
        q: 0,
    };
    for _ in 0..4 * a.len() + 8 {
        // The most violated row, by distance. A violated row with no normal no δ can meet: a
        // clearance row of the point the task holds on its path, projected onto the null space.
        let mut p = None;
        let mut worst = 0.0;
        for k in 0..a.len() {
            let s = a[k].dot(&x) - h[k];
            if s >= -TOL * (1.0 + h[k].abs()) {
                continue;
            }
            // Only a violated row's length is needed (a square root each, every round).
            let norm = a[k].norm();
            if norm <= 1e-12 {
                return Outcome::Infeasible;
            }
            if s / norm < worst {
                (worst, p) = (s / norm, Some(k));
            }
        }
        let Some(p) = p else {
            return Outcome::Solved(x);
        };
        let mut up = 0.0;
        for _ in 0..2 * N + 2 {
            let Some((r, z)) = act.split(a, &a[p]) else {
                return Outcome::Undecided;
            };
            // The dual step to the first multiplier that would turn negative.
            let (mut t1, mut l) = (f64::INFINITY, usize::MAX);
            for j in 0..act.q {
                if r[j] > 1e-14 && act.u[j] / r[j] < t1 {
                    (t1, l) = (act.u[j] / r[j], j);
                }
            }
            let zz = z.norm_squared();
            let s_p = a[p].dot(&x) - h[p];
            let t2 = if zz > 1e-20 * (1.0 + a[p].norm_squared()) {
                -s_p / zz
            } else {
                f64::INFINITY
            };
            let t = t1.min(t2);
            if !t.is_finite() {
                return Outcome::Infeasible;
            }
            for j in 0..act.q {
                act.u[j] -= t * r[j];
            }
            up += t;
            if t2.is_finite() {
                x += z * t;
            }
            if t == t2 {
                if act.q == N {
                    return Outcome::Undecided;
                }
                act.idx[act.q] = p;
                act.u[act.q] = up;
                act.q += 1;
                break;
            }
            act.drop(l);
        }
    }
    Outcome::Undecided
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn projects_onto_one_and_two_half_spaces_and_detects_infeasibility() {
        type V = Vector3<f64>;
        // x ≥ 1: δ = (1, 0, 0).
        let solved = |o: Outcome<3>| match o {
            Outcome::Solved(d) => d,
            other => panic!("{other:?}"),
        };
        let d = solved(solve::<3>(&[V::new(1.0, 0.0, 0.0)], &[1.0]));
        assert!((d - V::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        // x + y ≥ 2 and y ≥ 1.5: the corner (0.5, 1.5, 0).
        let d = solved(solve::<3>(
            &[V::new(1.0, 1.0, 0.0), V::new(0.0, 1.0, 0.0)],
            &[2.0, 1.5],
        ));
        assert!((d - V::new(0.5, 1.5, 0.0)).norm() < 1e-12, "{d}");
        // An inactive row changes nothing; x ≥ 1 and −x ≥ 0 cannot both hold.
        let d = solved(solve::<3>(
            &[V::new(0.0, 0.0, 1.0), V::new(1.0, 0.0, 0.0)],
            &[-5.0, 1.0],
        ));
        assert!((d - V::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        assert_eq!(
            solve::<3>(
                &[V::new(1.0, 0.0, 0.0), V::new(-1.0, 0.0, 0.0)],
                &[1.0, 0.0]
            ),
            Outcome::Infeasible
        );
        // A violated row with a vanishing normal: nothing meets it (it once read "solved",
        // δ = 0, and a Panda's hand link entered a sphere its path runs through).
        assert_eq!(
            solve::<3>(&[V::new(1.0, 0.0, 0.0), V::zeros()], &[1.0, 0.5]),
            Outcome::Infeasible
        );
        // Met already, it is no constraint.
        let d = solved(solve::<3>(
            &[V::new(1.0, 0.0, 0.0), V::zeros()],
            &[1.0, -0.5],
        ));
        assert!((d - V::new(1.0, 0.0, 0.0)).norm() < 1e-12);
    }

    #[test]
    fn agrees_with_a_brute_force_projection_on_random_problems() {
        // Random feasible problems in 4-D: the answer meets every row and no feasible point
        // of a dense random sample is closer to the origin.
        let mut rnd = crate::basics::rng::uniform(12345u64);
        for _ in 0..200 {
            let m = 6;
            let rows: Vec<VecN<4>> = (0..m).map(|_| VecN::<4>::from_fn(|_, _| rnd())).collect();
            let x0 = VecN::<4>::from_fn(|_, _| rnd()); // a feasible point by construction
            let h: Vec<f64> = rows.iter().map(|a| a.dot(&x0) - rnd().abs()).collect();
            let Outcome::Solved(d) = solve(&rows, &h) else {
                panic!("a feasible problem");
            };
            for (a, hk) in rows.iter().zip(&h) {
                assert!(a.dot(&d) >= hk - 1e-9);
            }
            assert!(d.norm() <= x0.norm() + 1e-12);
            for _ in 0..200 {
                let y = d + VecN::<4>::from_fn(|_, _| 0.05 * rnd());
                if rows.iter().zip(&h).all(|(a, hk)| a.dot(&y) >= *hk) {
                    assert!(y.norm() >= d.norm() - 1e-12);
                }
            }
        }
    }
}
