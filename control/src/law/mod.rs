//! The resolved-acceleration control law of docs/science.md, "The control law" (eqs. 1, 11, 13).
//!
//! q̈ = J⁺(p̈_d + K_v(ṗ_d − Jq̇) + K_p(p_d − p) − J̇q̇) + α(I − J⁺J)η − μ[q̇(t) − q̇(t−τ)]
//!
//! [`LawParams`] is a small `Copy` block with no dimension parameter: the daemon swaps a whole
//! validated block at a tick boundary, and the offline tools share exactly the same code. The
//! evaluation is a few hundred flops on the stack; it never allocates and never produces NaN from
//! finite inputs (damped least squares near singularities, a non-finite guard at the end).
//!
//! The safety filter ([`crate::safety`]) runs last, on the whole command: it is part of the
//! evaluation so that the offline simulation, the analysis and the daemon all get the same
//! filtered command, and a disabled filter costs one branch.

pub mod block;
pub mod core;
pub mod metric;
pub mod pipeline;
pub mod spatial;

pub use self::block::ParamBlock;
pub use self::core::{LawCore, LoopFeedback, Secondary};
use crate::arm::{ArmModel, Jac, Kinematics, VecN};
use crate::basics::{flags, wrap_angle};
use crate::resolve::ControlOutput;
use crate::safety::{self, SafetyParams};
use crate::secondary::{self, ObstacleSet, PotentialWeights};
use crate::task::Path;
use nalgebra::SMatrix;
use nalgebra::Vector3;
use pipeline::{ArmSide, Gains, TaskRows};

type Vec3 = Vector3<f64>;

/// A registered task's value and η at (t, q, q̇), given the tool point, its 6 × N Jacobian
/// (column-major, rows 0-2 linear, 3-5 angular) and the joint limits.
#[allow(clippy::too_many_arguments)]
pub(crate) fn custom_eta<const N: usize>(
    index: u8,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    tip: [f64; 3],
    jacobian: &SMatrix<f64, 6, N>,
    safety: &SafetyParams,
) -> (f64, Option<VecN<N>>) {
    let input = crate::secondary::custom::NullTaskInput {
        t,
        q: q.as_slice(),
        qd: qd.as_slice(),
        tip,
        jacobian: jacobian.as_slice(),
        q_min: &safety.q_min[..N],
        q_max: &safety.q_max[..N],
    };
    let mut eta = VecN::<N>::zeros();
    let value = crate::secondary::custom::call(index, &input, eta.as_mut_slice());
    (value, Some(eta))
}

/// The planar arm's law: the [`LawCore`] every arm has, and the plane's circle, discs and
/// steering.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LawParams {
    pub core: LawCore,
    /// The path in the arm's plane ([`Path::in_the_plane`]).
    pub task: Path,
    pub obstacles: ObstacleSet,
    pub weights: PotentialWeights,
    /// A planned clean cycle to steer the self-motion onto ([`crate::plan`]); planar 3-link
    /// arm only. None: the law as the paper has it.
    pub steer: Option<crate::steer::Steer>,
}

/// The pull towards the planned cycle at `t`, in the null space: (I − J⁺J)(q̈* + K_p(q* − q) +
/// K_d(q̇* − q̇)). The cycle's own acceleration is fed forward, so an arm on the cycle stays on
/// it instead of lagging behind. Only the first three joints have a plan.
#[inline]
fn steering<const N: usize>(
    s: &crate::steer::Steer,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    j: &Jac<N>,
    jpinv: &nalgebra::SMatrix<f64, N, 2>,
) -> VecN<N> {
    let r = s.cycle.sample(t);
    let mut v = VecN::<N>::zeros();
    for i in 0..N.min(3) {
        let e = wrap_angle(r.q[i] - q[i]);
        v[i] = r.qdd[i] + s.kp * e + s.kd * (r.qd[i] - qd[i]);
    }
    v - jpinv * (j * v)
}

/// The joint-space pull along a running detour: q̈_ref + K_p(q_ref − q) + K_d(q̇_ref − q̇), in
/// the full joint space (the hand leaves its path on purpose), for the first three joints.
#[inline]
fn detour_pull<const N: usize>(
    s: &crate::steer::Steer,
    d: &crate::steer::DetourTable,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
) -> VecN<N> {
    let w = std::f64::consts::TAU * crate::steer::DETOUR_HZ;
    let (kp, kd) = (w * w, 2.0 * w);
    let r = d.sample(t, &s.cycle);
    let mut v = VecN::<N>::zeros();
    for i in 0..N.min(3) {
        let e = wrap_angle(r.q[i] - q[i]);
        v[i] = r.qdd[i] + kp * e + kd * (r.qd[i] - qd[i]);
    }
    v
}

/// The planar arm's side of the law: the closed-form kinematics, the circle in the plane, the
/// paper's secondary tasks, the planned cycle and its detour, discs against the links.
struct PlanarSide<'a, const N: usize> {
    params: &'a LawParams,
    model: &'a ArmModel<N>,
    phi: f64,
    kin: &'a mut Kinematics<N>,
}

impl<const N: usize> PlanarSide<'_, N> {
    /// The steering and its detour, when one is under way.
    fn detour(&self) -> Option<(&crate::steer::Steer, &crate::steer::DetourTable)> {
        // By reference: the table is kilobytes, and this runs every tick.
        let s = self.params.steer.as_ref()?;
        s.detour.as_ref().map(|d| (s, d))
    }
}

impl<const N: usize> ArmSide<N, 2> for PlanarSide<'_, N> {
    #[inline]
    fn pinv(
        &self,
        j: &Jac<N>,
        threshold: f64,
        lambda_max: f64,
        _smin_wanted: bool,
    ) -> (SMatrix<f64, N, 2>, f64, f64) {
        // The 2×2 closed form has σ_min for a square root: no reason to skip it.
        crate::resolve::damped_pinv(j, threshold, lambda_max)
    }

    #[inline]
    fn gains(&self, t: f64) -> Gains<'_> {
        self.params.core.gains(t)
    }

    #[inline]
    fn task(&mut self, t: f64, q: &VecN<N>, qd: &VecN<N>) -> TaskRows<N, 2> {
        let p = self.params;
        self.model.kinematics(self.phi, q, qd, self.kin);
        let kin = &*self.kin;
        let (tp, tv, ta) = p.task.at_xy(t);
        let j: Jac<N> = kin.j;
        let err = tp - kin.p;
        TaskRows {
            acc: ta + (tv - j * qd) * p.core.kv + err * p.core.kp - kin.jdot_qd,
            j,
            position_error: err.norm(),
            orientation_error: 0.0,
            p: Vec3::new(kin.p.x, kin.p.y, 0.0),
            p_desired: Vec3::new(tp.x, tp.y, 0.0),
        }
    }

    #[inline]
    fn steering(&self) -> bool {
        self.params.steer.is_some()
    }

    #[inline]
    fn secondary(
        &mut self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &Jac<N>,
    ) -> (f64, Option<VecN<N>>) {
        let p = self.params;
        match p.core.secondary {
            Secondary::None => (0.0, None),
            Secondary::Manipulability => {
                let (w, g) = self.model.manipulability(q, self.kin);
                (w, Some(g))
            }
            Secondary::Centring => {
                let (c, g) =
                    secondary::spatial::centring(q, &p.core.safety.q_min, &p.core.safety.q_max);
                (c, Some(-g))
            }
            Secondary::Obstacles => {
                let (h, g) = secondary::potential(self.kin, &p.obstacles, p.weights);
                (h, Some(-g))
            }
            Secondary::Custom(index) => {
                // The plane's tool point and its Jacobian as a chain's: x and y rows, and the
                // turn about z every joint adds.
                let jac = SMatrix::<f64, 6, N>::from_fn(|r, c| match r {
                    0 | 1 => j[(r, c)],
                    5 => 1.0,
                    _ => 0.0,
                });
                let tip = [self.kin.p.x, self.kin.p.y, 0.0];
                custom_eta(index, t, q, qd, tip, &jac, &p.core.safety)
            }
        }
    }

    #[inline]
    fn feedback_held(&self, t: f64) -> bool {
        self.detour()
            .is_some_and(|(_, d)| t < d.t_arrive + self.params.core.tau)
    }

    #[inline]
    fn takeover(&self, t: f64, q: &VecN<N>, qd: &VecN<N>) -> Option<(VecN<N>, u32)> {
        let (s, d) = self.detour().filter(|(_, d)| d.running(t))?;
        Some((detour_pull(s, d, t, q, qd), flags::DETOUR))
    }

    #[inline]
    fn shape(
        &self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &Jac<N>,
        jpinv: &SMatrix<f64, N, 2>,
        qdd: &mut VecN<N>,
    ) {
        if let Some(s) = &self.params.steer {
            *qdd += steering(s, t, q, qd, j, jpinv);
        }
    }

    #[inline]
    fn filter(
        &self,
        q: &VecN<N>,
        qd: &VecN<N>,
        _j: &Jac<N>,
        jpinv: &SMatrix<f64, N, 2>,
        qdd: &VecN<N>,
    ) -> safety::Filtered<N> {
        let p = self.params;
        let (model, kin) = (self.model, &*self.kin);
        safety::filter(
            &p.core.safety,
            model,
            &p.obstacles,
            kin,
            self.phi,
            q,
            qd,
            jpinv,
            qdd,
        )
    }

    #[inline]
    fn clearance(&self) -> (f64, bool) {
        if self.params.obstacles.is_empty() {
            (f64::INFINITY, false)
        } else {
            secondary::clearance(self.kin, &self.params.obstacles)
        }
    }

    #[inline]
    fn task_flags(&self, rows: &TaskRows<N, 2>) -> u32 {
        let target = nalgebra::Vector2::new(rows.p_desired.x, rows.p_desired.y);
        let from_base = (target - self.kin.points[0]).norm();
        if from_base > self.model.reach() || from_base < self.model.inner_reach() {
            flags::OUT_OF_REACH
        } else {
            0
        }
    }

    #[inline]
    fn base_rate(&self) -> f64 {
        self.kin.base_rate
    }
}

/// Evaluates the law at time `t` for state (φ, q, q̇) with delayed velocity q̇(t − τ).
///
/// `kin` is scratch; on return it holds the kinematics at the state.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn evaluate<const N: usize>(
    params: &LawParams,
    model: &ArmModel<N>,
    t: f64,
    phi: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    qd_delayed: &VecN<N>,
    kin: &mut Kinematics<N>,
) -> ControlOutput<N> {
    let x = (phi, q, qd);
    run(params, model, t, x, qd_delayed, kin, pipeline::Full)
}

/// [`evaluate`], or what else `out` asks for ([`pipeline::Output`]); `x` is (φ, q, q̇).
#[inline]
pub fn run<const N: usize, O: pipeline::Output<N>>(
    params: &LawParams,
    model: &ArmModel<N>,
    t: f64,
    (phi, q, qd): (f64, &VecN<N>, &VecN<N>),
    qd_delayed: &VecN<N>,
    kin: &mut Kinematics<N>,
    out: O,
) -> O::Value {
    let mut side = PlanarSide {
        params,
        model,
        phi,
        kin,
    };
    pipeline::run(&mut side, t, q, qd, qd_delayed, out)
}
