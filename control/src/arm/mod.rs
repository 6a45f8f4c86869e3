//! Planar arm kinematics: the fixed-base n-link arm and the free-floating-base variant.
//!
//! Both models fill the same [`Kinematics`] block so the control law never needs to know which
//! one it drives. The fixed base is the hot default and is written in closed form (suffix sums over
//! the links, one `sin_cos` per link). The floating base follows docs/science.md, "The free-floating base": the base attitude φ
//! is not actuated but follows from zero angular momentum, which makes the generalized Jacobian J*
//! a rational function of q; it is written once, generic over [`Real`], and differentiated with
//! dual numbers.
//!
//! Everything here works on fixed-size nalgebra types and stack arrays: no call allocates.

pub mod point;
pub mod spatial;

use crate::dual::{Dual, Real};
use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

pub type Vec2 = Vector2<f64>;
pub type VecN<const N: usize> = SVector<f64, N>;
pub type Jac<const N: usize> = SMatrix<f64, 2, N>;

/// Below this manipulability the gradient's 1/w factor is clamped (the arm is singular there).
pub const MANIPULABILITY_FLOOR: f64 = 1e-9;

/// Everything the control law and the secondary tasks need from the arm at one state.
#[derive(Clone, Copy, Debug)]
pub struct Kinematics<const N: usize> {
    /// End-effector position p.
    pub p: Vec2,
    /// Task Jacobian: J for the fixed base, the generalized J* for the floating base (ṗ = J q̇).
    pub j: Jac<N>,
    /// The velocity-product term J̇ q̇ (J̇* q̇), so that p̈ = J q̈ + J̇ q̇.
    pub jdot_qd: Vec2,
    /// Joint positions P_1 … P_n: link j runs from `points[j]` to `points[j + 1]` (the last to `p`).
    pub points: [Vec2; N],
    /// ∂P_j/∂q at fixed base attitude (the obstacle potential's chain rule).
    pub point_jac: [Jac<N>; N],
    /// ∂p/∂q at fixed base attitude (equals `j` for the fixed base).
    pub ee_jac: Jac<N>,
    /// Base attitude rate φ̇ (0 for the fixed base).
    pub base_rate: f64,
    /// φ̇ = base_rate_row · q̇ (zeros for the fixed base): how the joints turn the base.
    pub base_rate_row: VecN<N>,
}

impl<const N: usize> Default for Kinematics<N> {
    fn default() -> Self {
        Self {
            p: Vec2::zeros(),
            j: Jac::zeros(),
            jdot_qd: Vec2::zeros(),
            points: [Vec2::zeros(); N],
            point_jac: [Jac::zeros(); N],
            ee_jac: Jac::zeros(),
            base_rate: 0.0,
            base_rate_row: VecN::zeros(),
        }
    }
}

#[inline(always)]
fn perp(v: Vec2) -> Vec2 {
    Vec2::new(-v.y, v.x)
}

/// The fixed-base planar arm of docs/science.md, "The planar arm and its task", base at the origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedArm<const N: usize> {
    pub links: [f64; N],
}

impl<const N: usize> FixedArm<N> {
    pub fn new(links: [f64; N]) -> Self {
        Self { links }
    }

    /// Forward kinematics, J and J̇q̇ in one pass.
    pub fn kinematics(&self, q: &VecN<N>, qd: &VecN<N>, out: &mut Kinematics<N>) {
        // Segment vectors l_j u_j, their perpendiculars, and absolute angular rates.
        let mut seg = [Vec2::zeros(); N];
        let mut theta = 0.0;
        let mut theta_rate = 0.0;
        let mut jdot_qd = Vec2::zeros();
        for j in 0..N {
            theta += q[j];
            theta_rate += qd[j];
            let (s, c) = theta.sin_cos();
            seg[j] = Vec2::new(c, s) * self.links[j];
            jdot_qd -= seg[j] * (theta_rate * theta_rate);
        }
        let mut p = Vec2::zeros();
        for j in 0..N {
            out.points[j] = p;
            p += seg[j];
        }
        // Column k of J is Σ_{m ≥ k} l_m S u_m: a suffix sum.
        let mut acc = Vec2::zeros();
        for k in (0..N).rev() {
            acc += perp(seg[k]);
            out.j.set_column(k, &acc);
        }
        // ∂P_j/∂q_k = col_k − col_j for k < j, else 0.
        for j in 0..N {
            let colj = out.j.column(j).into_owned();
            let pj = &mut out.point_jac[j];
            for k in 0..N {
                let v = if k < j {
                    out.j.column(k) - colj
                } else {
                    Vec2::zeros()
                };
                pj.set_column(k, &v);
            }
        }
        out.p = p;
        out.ee_jac = out.j;
        out.jdot_qd = jdot_qd;
        out.base_rate = 0.0;
        out.base_rate_row = VecN::zeros();
    }

    /// Manipulability w = √det(JJᵀ) and its analytic gradient.
    ///
    /// ∂w/∂q_k = tr(adj(A) H_k Jᵀ) / w with A = JJᵀ and H_k = ∂J/∂q_k, whose column i is
    /// −Σ_{m ≥ max(i,k)} l_m u_m = −(p − P_{max(i,k)}).
    pub fn manipulability(&self, kin: &Kinematics<N>) -> (f64, VecN<N>) {
        let a = kin.j * kin.j.transpose();
        let det = a[(0, 0)] * a[(1, 1)] - a[(0, 1)] * a[(1, 0)];
        let w = det.max(0.0).sqrt();
        let adj = Matrix2::new(a[(1, 1)], -a[(0, 1)], -a[(1, 0)], a[(0, 0)]);
        let inv_w = 1.0 / w.max(MANIPULABILITY_FLOOR);
        // adj(A) J, column i: used against H_k's columns.
        let adj_j = adj * kin.j;
        let mut grad = VecN::<N>::zeros();
        for k in 0..N {
            let mut tr = 0.0;
            for i in 0..N {
                let r = kin.p - kin.points[i.max(k)];
                tr -= adj_j.column(i).dot(&r);
            }
            grad[k] = tr * inv_w;
        }
        (w, grad)
    }
}

/// The free-floating-base planar arm of docs/science.md, "The free-floating base".
///
/// The system's centre of mass stays at the origin and total momentum is zero, so the base
/// position and attitude rate follow from (φ, q, q̇). The default base is heavy (200 kg,
/// 200 kg·m²): with the paper's m₀ = 1 kg the circle is out of reach of the system's centre of mass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FloatingArm<const N: usize> {
    pub links: [f64; N],
    pub link_masses: [f64; N],
    pub link_inertias: [f64; N],
    pub base_mass: f64,
    pub base_inertia: f64,
    /// Distance l₀ from the base's centre of mass to joint 1, along the base x-axis.
    pub base_offset: f64,
}

/// The floating arm at attitude φ = 0, relative to the system's centre of mass.
#[derive(Clone, Copy)]
struct Frame0<T: Real, const N: usize> {
    p: [T; 2],
    /// J*₀ columns: ṗ₀ = J*₀ q̇.
    jstar: [[T; 2]; N],
    /// ∂p₀/∂q at fixed φ.
    ee_jac: [[T; 2]; N],
    points: [[T; 2]; N],
    point_jac: [[[T; 2]; N]; N],
    /// φ̇ = k · q̇, k = −H_bm / H_b.
    k: [T; N],
}

#[inline(always)]
fn cross<T: Real>(a: [T; 2], b: [T; 2]) -> T {
    a[0] * b[1] - a[1] * b[0]
}

impl<const N: usize> FloatingArm<N> {
    pub fn total_mass(&self) -> f64 {
        self.base_mass + self.link_masses.iter().sum::<f64>()
    }

    fn frame0<T: Real>(&self, q: &[T; N]) -> Frame0<T, N> {
        let zero = T::cst(0.0);
        let mut seg = [[zero; 2]; N]; // l_j u_j
        let mut sperp = [[zero; 2]; N]; // l_j S u_j
        let mut theta = zero;
        for j in 0..N {
            theta = theta + q[j];
            let (s, c) = theta.sin_cos();
            let l = self.links[j];
            seg[j] = [c.scale(l), s.scale(l)];
            sperp[j] = [-s.scale(l), c.scale(l)];
        }
        // Suffix sums col[k] = Σ_{m ≥ k} l_m S u_m; col[N] = 0.
        let mut col = [[zero; 2]; N];
        let mut acc = [zero; 2];
        for k in (0..N).rev() {
            acc = [acc[0] + sperp[k][0], acc[1] + sperp[k][1]];
            col[k] = acc;
        }
        let col_at = |j: usize| if j < N { col[j] } else { [zero; 2] };
        // Raw positions (base centre of mass at the origin) and raw Jacobians.
        let mut pts = [[zero; 2]; N];
        let mut com = [[zero; 2]; N];
        let mut com_jac = [[[zero; 2]; N]; N];
        let mut pt_jac = [[[zero; 2]; N]; N];
        let mut pos = [T::cst(self.base_offset), zero];
        for j in 0..N {
            pts[j] = pos;
            com[j] = [pos[0] + seg[j][0].scale(0.5), pos[1] + seg[j][1].scale(0.5)];
            let cj = col_at(j);
            for k in 0..N {
                if k < j {
                    pt_jac[j][k] = [col[k][0] - cj[0], col[k][1] - cj[1]];
                }
                if k <= j {
                    com_jac[j][k] = [
                        col[k][0] - cj[0] + sperp[j][0].scale(0.5),
                        col[k][1] - cj[1] + sperp[j][1].scale(0.5),
                    ];
                }
            }
            pos = [pos[0] + seg[j][0], pos[1] + seg[j][1]];
        }
        let ee = pos;
        // System centre of mass and its Jacobian (the base body contributes m₀·0).
        let inv_m = 1.0 / self.total_mass();
        let mut rcm = [zero; 2];
        let mut rcm_jac = [[zero; 2]; N];
        for j in 0..N {
            let m = self.link_masses[j] * inv_m;
            rcm = [rcm[0] + com[j][0].scale(m), rcm[1] + com[j][1].scale(m)];
            for k in 0..N {
                rcm_jac[k] = [
                    rcm_jac[k][0] + com_jac[j][k][0].scale(m),
                    rcm_jac[k][1] + com_jac[j][k][1].scale(m),
                ];
            }
        }
        let sub = |a: [T; 2], b: [T; 2]| [a[0] - b[0], a[1] - b[1]];
        // Angular momentum about the system centre of mass: L = H_b φ̇ + H_bm q̇.
        let x0 = [-rcm[0], -rcm[1]];
        let mut hb = T::cst(self.base_inertia + self.link_inertias.iter().sum::<f64>())
            + (x0[0] * x0[0] + x0[1] * x0[1]).scale(self.base_mass);
        let mut hbm = [zero; N];
        let mut inertia_suffix = 0.0;
        for k in (0..N).rev() {
            inertia_suffix += self.link_inertias[k];
            hbm[k] = T::cst(inertia_suffix)
                + cross(x0, [-rcm_jac[k][0], -rcm_jac[k][1]]).scale(self.base_mass);
        }
        for j in 0..N {
            let x = sub(com[j], rcm);
            hb = hb + (x[0] * x[0] + x[1] * x[1]).scale(self.link_masses[j]);
            for k in 0..N {
                let xk = sub(com_jac[j][k], rcm_jac[k]);
                hbm[k] = hbm[k] + cross(x, xk).scale(self.link_masses[j]);
            }
        }
        let mut kvec = [zero; N];
        for k in 0..N {
            kvec[k] = -hbm[k] / hb;
        }
        let p = sub(ee, rcm);
        let mut out = Frame0 {
            p,
            jstar: [[zero; 2]; N],
            ee_jac: [[zero; 2]; N],
            points: [[zero; 2]; N],
            point_jac: [[[zero; 2]; N]; N],
            k: kvec,
        };
        for k in 0..N {
            let j0 = sub(col[k], rcm_jac[k]);
            out.ee_jac[k] = j0;
            // J*₀ = J₀ + S p₀ kᵀ
            out.jstar[k] = [j0[0] - p[1] * kvec[k], j0[1] + p[0] * kvec[k]];
        }
        for j in 0..N {
            out.points[j] = sub(pts[j], rcm);
            for k in 0..N {
                out.point_jac[j][k] = sub(pt_jac[j][k], rcm_jac[k]);
            }
        }
        out
    }

    fn dual_frame(&self, q: &VecN<N>, dir: &VecN<N>) -> Frame0<Dual, N> {
        let mut qd = [Dual::default(); N];
        for i in 0..N {
            qd[i] = Dual::new(q[i], dir[i]);
        }
        self.frame0(&qd)
    }

    /// Base attitude rate φ̇ = −H_b⁻¹ H_bm q̇.
    pub fn base_rate(&self, q: &VecN<N>, qd: &VecN<N>) -> f64 {
        let f = self.frame0::<f64>(&(*q).into());
        (0..N).map(|k| f.k[k] * qd[k]).sum()
    }

    /// Position of the base's centre of mass, for plotting and bridges.
    pub fn base_position(&self, phi: f64, q: &VecN<N>) -> Vec2 {
        let f = self.frame0::<f64>(&(*q).into());
        let rot = nalgebra::Rotation2::new(phi);
        rot * (Vec2::new(f.points[0][0], f.points[0][1]) - Vec2::new(self.base_offset, 0.0))
    }

    pub fn kinematics(&self, phi: f64, q: &VecN<N>, qd: &VecN<N>, out: &mut Kinematics<N>) {
        let f = self.frame0::<f64>(&(*q).into());
        let rot = nalgebra::Rotation2::new(phi);
        let v = |a: [f64; 2]| rot * Vec2::new(a[0], a[1]);
        let mut jstar0 = Jac::<N>::zeros();
        let mut phidot = 0.0;
        for k in 0..N {
            jstar0.set_column(k, &Vec2::new(f.jstar[k][0], f.jstar[k][1]));
            out.j.set_column(k, &v(f.jstar[k]));
            out.ee_jac.set_column(k, &v(f.ee_jac[k]));
            phidot += f.k[k] * qd[k];
            out.base_rate_row[k] = f.k[k];
        }
        for j in 0..N {
            out.points[j] = v(f.points[j]);
            for k in 0..N {
                out.point_jac[j].set_column(k, &v(f.point_jac[j][k]));
            }
        }
        out.p = v(f.p);
        out.base_rate = phidot;
        // J̇* q̇ = R(φ) [φ̇ S J*₀ q̇ + (D_q J*₀ · q̇) q̇]; the directional derivative comes from one
        // dual-number pass along q̇.
        let d = self.dual_frame(q, qd);
        let mut djq = Vec2::zeros();
        for k in 0..N {
            djq += Vec2::new(d.jstar[k][0].du, d.jstar[k][1].du) * qd[k];
        }
        let v0 = jstar0 * qd;
        out.jdot_qd = rot * (perp(v0) * phidot + djq);
    }

    /// Manipulability of J* (rotation-invariant, so computed at φ = 0) and its gradient in q,
    /// one dual-number pass per joint.
    pub fn manipulability(&self, q: &VecN<N>) -> (f64, VecN<N>) {
        let mut grad = VecN::<N>::zeros();
        let mut w = 0.0;
        for k in 0..N {
            let mut dir = VecN::<N>::zeros();
            dir[k] = 1.0;
            let f = self.dual_frame(q, &dir);
            let (mut a, mut b, mut c) = (Dual::cst(0.0), Dual::cst(0.0), Dual::cst(0.0));
            for col in &f.jstar {
                a = a + col[0] * col[0];
                b = b + col[0] * col[1];
                c = c + col[1] * col[1];
            }
            let det = a * c - b * b;
            w = det.re.max(0.0).sqrt();
            grad[k] = det.du / (2.0 * w.max(MANIPULABILITY_FLOOR));
        }
        (w, grad)
    }
}

/// The plant model the simulation and the control law run on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ArmModel<const N: usize> {
    Fixed(FixedArm<N>),
    Floating(FloatingArm<N>),
}

impl<const N: usize> ArmModel<N> {
    pub fn links(&self) -> &[f64; N] {
        match self {
            ArmModel::Fixed(a) => &a.links,
            ArmModel::Floating(a) => &a.links,
        }
    }

    pub fn is_floating(&self) -> bool {
        matches!(self, ArmModel::Floating(_))
    }

    /// Total reach Σ l_j, measured from joint 1.
    pub fn reach(&self) -> f64 {
        self.links().iter().sum()
    }

    /// Inner radius of the annular workspace about joint 1: max(0, 2 max l − Σ l).
    pub fn inner_reach(&self) -> f64 {
        let l = self.links();
        let max = l.iter().cloned().fold(0.0, f64::max);
        (2.0 * max - self.reach()).max(0.0)
    }

    #[inline]
    pub fn kinematics(&self, phi: f64, q: &VecN<N>, qd: &VecN<N>, out: &mut Kinematics<N>) {
        match self {
            ArmModel::Fixed(a) => a.kinematics(q, qd, out),
            ArmModel::Floating(a) => a.kinematics(phi, q, qd, out),
        }
    }

    /// w and ∇w; `kin` must be this model's kinematics at q.
    #[inline]
    pub fn manipulability(&self, q: &VecN<N>, kin: &Kinematics<N>) -> (f64, VecN<N>) {
        match self {
            ArmModel::Fixed(a) => a.manipulability(kin),
            ArmModel::Floating(a) => a.manipulability(q),
        }
    }
}
