//! Every model quantity at one state, as plain numbers: what `chaosctl robot eval` prints and
//! what the golden tests compare with pinocchio. Not for the tick (it allocates its outputs).

use super::chain::Chain;
use super::fixed::{Model, VecN};
use super::kinematics::TipKinematics;
use super::ModelError;
use serde::Serialize;

/// The quantities of one state, row-major, in the base frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evaluation {
    /// 4×4 pose of the tip in the base frame.
    pub tip_pose: Vec<f64>,
    /// 6×n, rows vx vy vz wx wy wz.
    pub jacobian: Vec<f64>,
    /// The tip origin's classical acceleration at q̈ = 0 (linear, then angular).
    pub jdot_qd: Vec<f64>,
    /// n×n.
    pub mass_matrix: Vec<f64>,
    /// τ = M q̈ + C q̇ + g.
    pub rnea: Vec<f64>,
    /// g(q).
    pub gravity: Vec<f64>,
    /// q̈ from τ.
    pub aba: Vec<f64>,
}

impl Evaluation {
    /// Every quantity with its name, in the order and words of `robot eval --json` and the
    /// pinocchio fixtures.
    pub fn named(&self) -> [(&'static str, &[f64]); 7] {
        [
            ("tip_pose", &self.tip_pose),
            ("jacobian", &self.jacobian),
            ("jdot_qd", &self.jdot_qd),
            ("mass_matrix", &self.mass_matrix),
            ("rnea", &self.rnea),
            ("gravity", &self.gravity),
            ("aba", &self.aba),
        ]
    }
}

/// Which of the state's vectors was the wrong length.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{name} has {got} entries; the chain has {n} joints")]
pub struct LengthError {
    pub name: &'static str,
    pub got: usize,
    pub n: usize,
}

impl Chain {
    /// Evaluates every quantity at (q, q̇, q̈, τ); each slice must have [`Chain::dof`] entries.
    ///
    /// ```
    /// # use control::model::{builtin, Chain};
    /// let chain = Chain::from_urdf(builtin("planar3").unwrap(), None, None).unwrap();
    /// let e = chain.evaluate(&[0.0; 3], &[0.0; 3], &[0.0; 3], &[0.0; 3]).unwrap();
    /// assert_eq!(e.tip_pose[3], 3.0); // x of the tip, row-major 4×4
    /// assert!(chain.evaluate(&[0.0; 2], &[0.0; 3], &[0.0; 3], &[0.0; 3]).is_err());
    /// ```
    pub fn evaluate(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        tau: &[f64],
    ) -> Result<Evaluation, LengthError> {
        let n = self.dof();
        for (name, v) in [("q", q), ("qd", qd), ("qdd", qdd), ("tau", tau)] {
            if v.len() != n {
                return Err(LengthError {
                    name,
                    got: v.len(),
                    n,
                });
            }
        }
        Ok(crate::with_dof!(n, N => {
            let model: Model<N> = self.model::<N>().expect("size checked above");
            evaluate_fixed(&model, q, qd, qdd, tau)
        }))
    }
}

fn evaluate_fixed<const N: usize>(
    model: &Model<N>,
    q: &[f64],
    qd: &[f64],
    qdd: &[f64],
    tau: &[f64],
) -> Evaluation {
    let v = |s: &[f64]| VecN::<N>::from_column_slice(s);
    let (q, qd, qdd, tau) = (v(q), v(qd), v(qdd), v(tau));
    let mut k = TipKinematics::default();
    model.tip_kinematics(&q, &qd, &mut k);
    let row_major = |rows: usize, cols: usize, at: &dyn Fn(usize, usize) -> f64| {
        (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (r, c)))
            .map(|(r, c)| at(r, c))
            .collect::<Vec<f64>>()
    };
    let pose = k.frames.tip.matrix();
    let m = model.mass_matrix(&q);
    Evaluation {
        tip_pose: row_major(4, 4, &|r, c| pose[(r, c)]),
        jacobian: row_major(6, N, &|r, c| k.jacobian[(r, c)]),
        jdot_qd: k.jdot_qd.iter().copied().collect(),
        mass_matrix: row_major(N, N, &|r, c| m[(r, c)]),
        rnea: model.rnea(&q, &qd, &qdd).iter().copied().collect(),
        gravity: model.gravity_torques(&q).iter().copied().collect(),
        aba: model.aba(&q, &qd, &tau).iter().copied().collect(),
    }
}

impl From<LengthError> for ModelError {
    fn from(e: LengthError) -> Self {
        ModelError::Dof {
            chain: e.n,
            asked: e.got,
        }
    }
}
