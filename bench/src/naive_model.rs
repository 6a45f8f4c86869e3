//! The textbook alternative to `control::model`: the robot model the way someone without care
//! for cost would write it, with heap-allocated dynamic matrices.
//!
//! * Forward kinematics multiplies one 4×4 homogeneous matrix per joint, each joint's motion
//!   built by Rodrigues' formula about its axis (the chain's frames are turned so that the axis
//!   is local z, but the formula is the general one).
//! * The Jacobian is the geometric one, column by column; J̇ is formed as a matrix (each column's
//!   time derivative) and multiplied by q̇.
//! * RNEA is Featherstone's, in each body's own frame, with 6×6 Plücker transforms, spatial
//!   inertias and cross-product matrices as `DMatrix`.
//! * CRBA is n + 1 RNEA calls: column i of M is rnea(q, 0, eᵢ) − rnea(q, 0, 0).
//! * ABA is M⁻¹(τ − h) by LU, with h = rnea(q, q̇, 0).
//!
//! It reads the same [`control::model::Chain`] as chaosd's fixed-size model (placements, bodies,
//! joint kinds), and a test shows it computes the same numbers to 1e-9, so the benchmark compares
//! equal work.

use control::model::Chain;
use nalgebra::{DMatrix, DVector};

/// A serial chain as dynamic matrices.
#[derive(Debug, Clone)]
pub struct NaiveModel {
    pub n: usize,
    /// Joint i's frame in body i−1's frame (4×4).
    placement: Vec<DMatrix<f64>>,
    /// Joint i's axis in its own frame (3).
    axis: Vec<DVector<f64>>,
    prismatic: Vec<bool>,
    mass: Vec<f64>,
    /// Centre of mass in body i's frame (3).
    com: Vec<DVector<f64>>,
    /// Rotational inertia about the centre of mass, body i's axes (3×3).
    inertia: Vec<DMatrix<f64>>,
    /// The tip in body n−1's frame (4×4).
    tip: DMatrix<f64>,
    /// Gravity in the base frame (3).
    gravity: DVector<f64>,
}

/// The tip's pose (4×4), Jacobian (6×n, rows v then ω) and J̇q̇ (6), in the base frame.
#[derive(Debug, Clone)]
#[allow(dead_code)] // the tests read them; the benchmark only times their making
pub struct NaiveTip {
    pub pose: DMatrix<f64>,
    pub jacobian: DMatrix<f64>,
    pub jdot_qd: DVector<f64>,
}

fn skew(v: &DVector<f64>) -> DMatrix<f64> {
    DMatrix::from_row_slice(
        3,
        3,
        &[0.0, -v[2], v[1], v[2], 0.0, -v[0], -v[1], v[0], 0.0],
    )
}

fn cross(a: &DVector<f64>, b: &DVector<f64>) -> DVector<f64> {
    skew(a) * b
}

/// Rodrigues: the rotation by `angle` about the unit `axis`.
fn rodrigues(axis: &DVector<f64>, angle: f64) -> DMatrix<f64> {
    let k = skew(axis);
    DMatrix::identity(3, 3) + &k * angle.sin() + &k * &k * (1.0 - angle.cos())
}

fn homogeneous(rot: &DMatrix<f64>, pos: &DVector<f64>) -> DMatrix<f64> {
    let mut t = DMatrix::identity(4, 4);
    t.view_mut((0, 0), (3, 3)).copy_from(rot);
    t.view_mut((0, 3), (3, 1)).copy_from(pos);
    t
}

fn rotation(t: &DMatrix<f64>) -> DMatrix<f64> {
    t.view((0, 0), (3, 3)).into_owned()
}

fn translation(t: &DMatrix<f64>) -> DVector<f64> {
    DVector::from_iterator(3, t.view((0, 3), (3, 1)).iter().copied())
}

/// The Plücker transform taking motion vectors (ω, v) from a parent frame to a child frame
/// whose pose in the parent is `t`.
fn plucker(t: &DMatrix<f64>) -> DMatrix<f64> {
    let rt = rotation(t).transpose();
    let p = translation(t);
    let mut x = DMatrix::zeros(6, 6);
    x.view_mut((0, 0), (3, 3)).copy_from(&rt);
    x.view_mut((3, 3), (3, 3)).copy_from(&rt);
    x.view_mut((3, 0), (3, 3)).copy_from(&(-&rt * skew(&p)));
    x
}

/// The motion cross-product matrix: `crm(v) m = v ×ₘ m`.
fn crm(v: &DVector<f64>) -> DMatrix<f64> {
    let w = skew(&v.rows(0, 3).into_owned());
    let vl = skew(&v.rows(3, 3).into_owned());
    let mut x = DMatrix::zeros(6, 6);
    x.view_mut((0, 0), (3, 3)).copy_from(&w);
    x.view_mut((3, 3), (3, 3)).copy_from(&w);
    x.view_mut((3, 0), (3, 3)).copy_from(&vl);
    x
}

/// The force cross-product matrix: `crf(v) f = v ×* f = −crm(v)ᵀ f`.
fn crf(v: &DVector<f64>) -> DMatrix<f64> {
    -crm(v).transpose()
}

impl NaiveModel {
    pub fn new(chain: &Chain) -> Self {
        let pose4 =
            |p: &control::model::Pose| DMatrix::from_column_slice(4, 4, p.matrix().as_slice());
        let v3 = |v: &nalgebra::Vector3<f64>| DVector::from_column_slice(v.as_slice());
        Self {
            n: chain.dof(),
            placement: chain.joints.iter().map(|j| pose4(&j.placement)).collect(),
            // The turned frames put every axis on local z.
            axis: chain
                .joints
                .iter()
                .map(|_| DVector::from_column_slice(&[0.0, 0.0, 1.0]))
                .collect(),
            prismatic: chain.joints.iter().map(|j| j.kind.is_prismatic()).collect(),
            mass: chain.joints.iter().map(|j| j.body.mass).collect(),
            com: chain.joints.iter().map(|j| v3(&j.body.com)).collect(),
            inertia: chain
                .joints
                .iter()
                .map(|j| DMatrix::from_column_slice(3, 3, j.body.inertia.as_slice()))
                .collect(),
            tip: pose4(&chain.tip_placement),
            gravity: v3(&chain.gravity),
        }
    }

    /// Body i's frame in body i−1's frame at q_i: placement · joint motion.
    fn joint_transform(&self, i: usize, qi: f64) -> DMatrix<f64> {
        let motion = if self.prismatic[i] {
            homogeneous(&DMatrix::identity(3, 3), &(&self.axis[i] * qi))
        } else {
            homogeneous(&rodrigues(&self.axis[i], qi), &DVector::zeros(3))
        };
        &self.placement[i] * motion
    }

    /// Every body's frame in the base frame, then the tip's (n + 1 matrices).
    pub fn forward_kinematics(&self, q: &DVector<f64>) -> Vec<DMatrix<f64>> {
        let mut out = Vec::new();
        let mut t = DMatrix::identity(4, 4);
        for i in 0..self.n {
            t = &t * self.joint_transform(i, q[i]);
            out.push(t.clone());
        }
        out.push(&t * &self.tip);
        out
    }

    /// The tip's pose, geometric Jacobian and J̇q̇.
    pub fn tip_kinematics(&self, q: &DVector<f64>, qd: &DVector<f64>) -> NaiveTip {
        let n = self.n;
        let frames = self.forward_kinematics(q);
        let p = translation(&frames[n]);
        let z: Vec<DVector<f64>> = (0..n)
            .map(|i| rotation(&frames[i]) * &self.axis[i])
            .collect();
        let o: Vec<DVector<f64>> = (0..n).map(|i| translation(&frames[i])).collect();
        let mut jac = DMatrix::zeros(6, n);
        for i in 0..n {
            if self.prismatic[i] {
                jac.view_mut((0, i), (3, 1)).copy_from(&z[i]);
            } else {
                jac.view_mut((0, i), (3, 1))
                    .copy_from(&cross(&z[i], &(&p - &o[i])));
                jac.view_mut((3, i), (3, 1)).copy_from(&z[i]);
            }
        }
        // The velocity of a point x fixed to body k: Σ_{j ≤ k} column j at x times q̇_j.
        let point_velocity = |x: &DVector<f64>, upto: usize| {
            let mut v = DVector::zeros(3);
            for j in 0..upto {
                if self.prismatic[j] {
                    v += &z[j] * qd[j];
                } else {
                    v += cross(&z[j], &(x - &o[j])) * qd[j];
                }
            }
            v
        };
        let p_dot = jac.rows(0, 3) * qd;
        // J̇ column by column: z_i turns with body i−1, o_i moves with it.
        let mut jdot = DMatrix::zeros(6, n);
        let mut w = DVector::zeros(3);
        for i in 0..n {
            let z_dot = cross(&w, &z[i]);
            if self.prismatic[i] {
                jdot.view_mut((0, i), (3, 1)).copy_from(&z_dot);
            } else {
                let o_dot = point_velocity(&o[i], i);
                let v = cross(&z_dot, &(&p - &o[i])) + cross(&z[i], &(&p_dot - o_dot));
                jdot.view_mut((0, i), (3, 1)).copy_from(&v);
                jdot.view_mut((3, i), (3, 1)).copy_from(&z_dot);
                w += &z[i] * qd[i];
            }
        }
        NaiveTip {
            pose: frames[n].clone(),
            jacobian: jac,
            jdot_qd: jdot * qd,
        }
    }

    /// Body i's spatial inertia about its frame's origin, in its axes (6×6, (ω, v) order).
    fn spatial_inertia(&self, i: usize) -> DMatrix<f64> {
        let m = self.mass[i];
        let cx = skew(&self.com[i]);
        let mut s = DMatrix::zeros(6, 6);
        s.view_mut((0, 0), (3, 3))
            .copy_from(&(&self.inertia[i] + &cx * cx.transpose() * m));
        s.view_mut((0, 3), (3, 3)).copy_from(&(&cx * m));
        s.view_mut((3, 0), (3, 3)).copy_from(&(cx.transpose() * m));
        s.view_mut((3, 3), (3, 3))
            .copy_from(&(DMatrix::identity(3, 3) * m));
        s
    }

    fn motion_subspace(&self, i: usize) -> DVector<f64> {
        let mut s = DVector::zeros(6);
        if self.prismatic[i] {
            s.rows_mut(3, 3).copy_from(&self.axis[i]);
        } else {
            s.rows_mut(0, 3).copy_from(&self.axis[i]);
        }
        s
    }

    /// τ = M q̈ + C q̇ + g, by Featherstone's RNEA in body coordinates.
    pub fn rnea(&self, q: &DVector<f64>, qd: &DVector<f64>, qdd: &DVector<f64>) -> DVector<f64> {
        let n = self.n;
        let mut x = Vec::new();
        let mut s = Vec::new();
        let mut f = Vec::new();
        let mut v = DVector::zeros(6);
        let mut a = DVector::zeros(6);
        a.rows_mut(3, 3).copy_from(&(-&self.gravity));
        for i in 0..n {
            let xi = plucker(&self.joint_transform(i, q[i]));
            let si = self.motion_subspace(i);
            let vj = &si * qd[i];
            v = &xi * &v + &vj;
            a = &xi * &a + &si * qdd[i] + crm(&v) * &vj;
            let inertia = self.spatial_inertia(i);
            f.push(&inertia * &a + crf(&v) * (&inertia * &v));
            x.push(xi);
            s.push(si);
        }
        let mut tau = DVector::zeros(n);
        for i in (0..n).rev() {
            tau[i] = s[i].dot(&f[i]);
            if i > 0 {
                let back = x[i].transpose() * &f[i];
                f[i - 1] += back;
            }
        }
        tau
    }

    /// g(q) = rnea(q, 0, 0).
    pub fn gravity_torques(&self, q: &DVector<f64>) -> DVector<f64> {
        let z = DVector::zeros(self.n);
        self.rnea(q, &z, &z)
    }

    /// M(q), column by column from RNEA.
    pub fn mass_matrix(&self, q: &DVector<f64>) -> DMatrix<f64> {
        let n = self.n;
        let zero = DVector::zeros(n);
        let g = self.rnea(q, &zero, &zero);
        let mut m = DMatrix::zeros(n, n);
        for i in 0..n {
            let mut e = DVector::zeros(n);
            e[i] = 1.0;
            m.set_column(i, &(self.rnea(q, &zero, &e) - &g));
        }
        m
    }

    /// q̈ = M⁻¹(τ − h) by LU.
    pub fn aba(&self, q: &DVector<f64>, qd: &DVector<f64>, tau: &DVector<f64>) -> DVector<f64> {
        let h = self.rnea(q, qd, &DVector::zeros(self.n));
        self.mass_matrix(q)
            .lu()
            .solve(&(tau - h))
            .expect("M is positive definite")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::model::{builtin, Model, TipKinematics};
    use nalgebra::SVector;

    /// splitmix64, in [−1, 1).
    fn uniform(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    fn agree<const N: usize>(chain: &Chain) {
        let model: Model<N> = chain.model::<N>().unwrap();
        let naive = NaiveModel::new(chain);
        let mut seed = 7;
        let close = |a: &[f64], b: &[f64], what: &str| {
            assert_eq!(a.len(), b.len(), "{what}");
            for (x, y) in a.iter().zip(b) {
                assert!(
                    (x - y).abs() < 1e-9 * (1.0 + y.abs()),
                    "{what}: {a:?} vs {b:?}"
                );
            }
        };
        for _ in 0..50 {
            let mut r = |scale: f64| SVector::<f64, N>::from_fn(|_, _| scale * uniform(&mut seed));
            let (q, qd, qdd, tau) = (r(3.0), r(2.0), r(5.0), r(20.0));
            let d = |v: &SVector<f64, N>| DVector::from_column_slice(v.as_slice());
            let mut k = TipKinematics::default();
            model.tip_kinematics(&q, &qd, &mut k);
            let t = naive.tip_kinematics(&d(&q), &d(&qd));
            close(
                t.pose.as_slice(),
                k.frames.tip.matrix().as_slice(),
                "tip pose",
            );
            close(t.jacobian.as_slice(), k.jacobian.as_slice(), "Jacobian");
            close(t.jdot_qd.as_slice(), k.jdot_qd.as_slice(), "J̇q̇");
            close(
                naive.rnea(&d(&q), &d(&qd), &d(&qdd)).as_slice(),
                model.rnea(&q, &qd, &qdd).as_slice(),
                "RNEA",
            );
            close(
                naive.gravity_torques(&d(&q)).as_slice(),
                model.gravity_torques(&q).as_slice(),
                "gravity",
            );
            close(
                naive.mass_matrix(&d(&q)).as_slice(),
                model.mass_matrix(&q).as_slice(),
                "CRBA",
            );
            close(
                naive.aba(&d(&q), &d(&qd), &d(&tau)).as_slice(),
                model.aba(&q, &qd, &tau).as_slice(),
                "ABA",
            );
        }
    }

    #[test]
    fn naive_and_chaosd_agree_on_the_panda() {
        agree::<7>(&Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap());
    }

    #[test]
    fn naive_and_chaosd_agree_on_the_ur5() {
        let text = include_str!("../../control/tests/fixtures/urdf/ur5.urdf");
        agree::<6>(&Chain::from_urdf(text, Some("base_link"), Some("tool0")).unwrap());
    }

    #[test]
    fn naive_and_chaosd_agree_on_the_quirks_chain() {
        // Prismatic joints, axes off x/y/z, a tilted base.
        let text = include_str!("../../control/tests/fixtures/urdf/quirks.urdf");
        let chain = Chain::from_urdf(text, Some("base"), Some("tcp")).unwrap();
        control::with_dof!(chain.dof(), N => agree::<N>(&chain));
    }

    #[test]
    fn naive_and_chaosd_agree_on_planar3() {
        agree::<3>(&Chain::from_urdf(builtin("planar3").unwrap(), None, None).unwrap());
    }
}
