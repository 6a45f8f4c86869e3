//! The textbook alternative to chaosd's law: heap-allocated dynamic matrices and an SVD-based
//! pseudo-inverse, as a straight port of a numpy script would be written. It computes the same
//! q̈ (a test checks this), so timing the two side by side shows what fixed sizes and closed forms
//! buy, on this machine, in the same run.

use control::{ArmModel, LawParams, VecN};
use nalgebra::{DMatrix, DVector};

/// q̈ for the fixed-base arm with manipulability ascent (μ = 0), with dynamic matrices.
pub fn law<const N: usize>(
    params: &LawParams,
    model: &ArmModel<N>,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
) -> DVector<f64> {
    let links = model.links();
    let n = N;
    let fk = |q: &DVector<f64>| {
        let mut p = DVector::zeros(2);
        let mut th = 0.0;
        for j in 0..n {
            th += q[j];
            p[0] += links[j] * th.cos();
            p[1] += links[j] * th.sin();
        }
        p
    };
    let jac = |q: &DVector<f64>| {
        let mut jm = DMatrix::zeros(2, n);
        let mut th = 0.0;
        let mut ths = vec![0.0; n];
        for j in 0..n {
            th += q[j];
            ths[j] = th;
        }
        for k in 0..n {
            for m in k..n {
                jm[(0, k)] -= links[m] * ths[m].sin();
                jm[(1, k)] += links[m] * ths[m].cos();
            }
        }
        jm
    };
    let qv = DVector::from_column_slice(q.as_slice());
    let qdv = DVector::from_column_slice(qd.as_slice());
    let j = jac(&qv);
    let jpinv = j.clone().pseudo_inverse(1e-12).expect("svd");
    // J̇q̇ by the analytic sum, as the reference does.
    let mut jdq = DVector::zeros(2);
    let (mut th, mut thd) = (0.0, 0.0);
    for m in 0..n {
        th += q[m];
        thd += qd[m];
        jdq[0] -= links[m] * th.cos() * thd * thd;
        jdq[1] -= links[m] * th.sin() * thd * thd;
    }
    let (tp, tv, ta) = params.task.at_xy(t);
    let pd = DVector::from_column_slice(tp.as_slice());
    let vd = DVector::from_column_slice(tv.as_slice());
    let ad = DVector::from_column_slice(ta.as_slice());
    let p = fk(&qv);
    let acc = &ad + (&vd - &j * &qdv) * params.core.kv + (&pd - &p) * params.core.kp - &jdq;
    // ∇w by the determinant formula with dynamic matrices.
    let a = &j * j.transpose();
    let w = a.determinant().max(0.0).sqrt();
    let ainv = a
        .clone()
        .try_inverse()
        .expect("invertible away from singularities");
    let mut grad = DVector::zeros(n);
    for k in 0..n {
        let mut h = DMatrix::zeros(2, n);
        let mut th = 0.0;
        let mut ths = vec![0.0; n];
        for m in 0..n {
            th += q[m];
            ths[m] = th;
        }
        for i in 0..n {
            for m in i.max(k)..n {
                h[(0, i)] -= links[m] * ths[m].cos();
                h[(1, i)] -= links[m] * ths[m].sin();
            }
        }
        grad[k] = w * (&ainv * &h * j.transpose()).trace();
    }
    let eye = DMatrix::<f64>::identity(n, n);
    &jpinv * acc + (eye - &jpinv * &j) * grad * params.core.alpha
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::{Config, Kinematics};

    /// The same evaluation through chaosd's law, for the equivalence test and the side-by-side.
    fn chaosd<const N: usize>(
        params: &LawParams,
        model: &ArmModel<N>,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
    ) -> VecN<N> {
        let mut k = Kinematics::default();
        control::law::evaluate(params, model, t, 0.0, q, qd, qd, &mut k).qdd
    }

    #[test]
    fn naive_and_chaosd_agree() {
        let cfg = Config::preset("paper").unwrap();
        let (p, m) = (cfg.law_params(), cfg.model::<3>());
        for (i, q) in [[0.0, 1.57, 1.57], [0.4, -0.9, 2.2], [1.0, 0.5, -1.2]]
            .iter()
            .enumerate()
        {
            let q = VecN::<3>::from(*q);
            let qd = VecN::<3>::new(0.3, -1.0, 2.0 * i as f64);
            let a = law(&p, &m, 0.37, &q, &qd);
            let b = chaosd(&p, &m, 0.37, &q, &qd);
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() < 1e-8 * (1.0 + b[k].abs()),
                    "{a} vs {b}"
                );
            }
        }
    }
}
