//! The control law of docs/science.md, "The control law" on a spatial arm, for a task of m = 3 or 6 rows.
//!
//! Only the task side is spatial: the tool point's error (and for the pose task the orientation
//! error as a rotation vector) with its feed-forward. Everything after the task acceleration is
//! [`crate::resolve`], the code the planar law runs, and the filter is the planar filter's solver
//! with capsule rows. One extra, optional term: null-space joint damping −k_d(I − J⁺J)q̇, the
//! classical remedy for the undamped self-motion of acceleration-level resolved-rate control
//! (Hsu, Hauser & Sastry 1989); it is off (k_d = 0) unless configured, so that the study can
//! compare it with the Pyragas term.

use super::metric::damped_pinv_weighted;
use super::pipeline::{ArmSide, Full, Gains, Output, TaskRows};
use super::LawCore;
use super::Secondary;
use crate::arm::spatial::CapsulePoints;
use crate::arm::spatial::SpatialArm;
use crate::arm::spatial::SpatialKinematics;
use crate::arm::spatial::VecN;
use crate::resolve::damped_pinv_deciding;
use crate::resolve::damped_pinv_m;
use crate::resolve::ControlOutput;
use crate::safety::Filtered;
use crate::secondary::spatial as sec;
use crate::secondary::spatial::SphereSet;
use crate::task::pose::orientation_error;
use crate::task::pose::SpatialTask;
use crate::task::Vec3;
use nalgebra::{SMatrix, Vector6};

/// Every tunable of the spatial law: a `Copy` block, like the planar [`crate::LawParams`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialParams {
    pub core: LawCore,
    pub task: SpatialTask,
    pub spheres: SphereSet,
    /// The obstacle potential's weight W.
    pub weight: f64,
    /// Null-space joint damping k_d ≥ 0 (0: the paper's law).
    pub null_damping: f64,
    /// The largest joint speed (rad/s) the secondary task's pull may ask of the self-motion
    /// ([`pull_scale`]); 0: no cap.
    pub null_speed: f64,
    /// The pseudo-inverse's joint weights D (metric D⁻²; [`crate::law::metric`]); None: the
    /// identity, the minimum-norm pseudo-inverse.
    pub joint_weights: Option<[f64; crate::basics::MAX_JOINTS]>,
    /// A planned clean cycle to steer the self-motion onto ([`crate::plan::spatial`]); it
    /// replaces the secondary task, as on the planar arm.
    pub steer: Option<crate::steer::SpatialSteer>,
}

/// A URDF chain's side of the law: the chain's kinematics, a spatial path (position or pose),
/// the spatial secondary tasks, the planned cycle's pull, capsules against spheres.
struct SpatialSide<'a, const N: usize> {
    params: &'a SpatialParams,
    arm: &'a SpatialArm<N>,
    kin: &'a mut SpatialKinematics<N>,
    /// The secondary task's η, kept for [`pull_scale`] in `shape` (zero while steering).
    eta: VecN<N>,
}

impl<const N: usize, const M: usize> ArmSide<N, M> for SpatialSide<'_, N> {
    #[inline]
    fn gains(&self, t: f64) -> Gains<'_> {
        self.params.core.gains(t)
    }

    #[inline]
    fn task(&mut self, t: f64, q: &VecN<N>, qd: &VecN<N>) -> TaskRows<N, M> {
        let p = self.params;
        debug_assert_eq!(M, p.task.kind.rows());
        self.arm.kinematics(q, qd, self.kin);
        let kin = &*self.kin;
        let target = p.task.at(t);
        let ep = target.p - kin.p;
        let eo = if M == 6 {
            orientation_error(&target.rot, &kin.rot)
        } else {
            Vec3::zeros()
        };
        let vel = kin.jac * qd;
        let desired = Vector6::new(
            target.a.x,
            target.a.y,
            target.a.z,
            target.wd.x,
            target.wd.y,
            target.wd.z,
        ) + (Vector6::new(
            target.v.x, target.v.y, target.v.z, target.w.x, target.w.y, target.w.z,
        ) - vel)
            * p.core.kv
            + Vector6::new(ep.x, ep.y, ep.z, eo.x, eo.y, eo.z) * p.core.kp
            - kin.jdot_qd;
        TaskRows {
            j: kin.jac.fixed_rows::<M>(0).into_owned(),
            acc: sec::rows::<M>(&desired),
            position_error: ep.norm(),
            orientation_error: eo.norm(),
            p: kin.p,
            p_desired: target.p,
        }
    }

    #[inline]
    fn pinv(
        &self,
        j: &SMatrix<f64, M, N>,
        threshold: f64,
        lambda_max: f64,
        smin_wanted: bool,
    ) -> (SMatrix<f64, N, M>, f64, f64) {
        match &self.params.joint_weights {
            None => damped_pinv_deciding(j, threshold, lambda_max, smin_wanted),
            Some(d) => damped_pinv_weighted(j, d, threshold, lambda_max),
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
        j: &SMatrix<f64, M, N>,
    ) -> (f64, Option<VecN<N>>) {
        let (value, eta) = self.secondary_task(t, q, qd, j);
        if let Some(e) = &eta {
            self.eta = *e;
        }
        (value, eta)
    }

    #[inline]
    fn shape(
        &self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
        jpinv: &SMatrix<f64, N, M>,
        qdd: &mut VecN<N>,
    ) {
        let p = self.params;
        if let Some(s) = &p.steer {
            *qdd += s.pull(t, q, qd, j, jpinv, qdd, &p.core.safety);
        }
        if p.null_damping != 0.0 {
            if p.null_speed > 0.0 {
                let pull = (self.eta - jpinv * (j * self.eta)) * p.core.alpha;
                let s = pull_scale(pull.norm(), p.null_damping, p.null_speed);
                if s < 1.0 {
                    *qdd -= pull * (1.0 - s);
                }
            }
            *qdd -= (qd - jpinv * (j * qd)) * p.null_damping;
        }
    }

    #[inline]
    fn filter(
        &self,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
        jpinv: &SMatrix<f64, N, M>,
        qdd: &VecN<N>,
    ) -> Filtered<N> {
        let p = self.params;
        let (arm, kin) = (self.arm, &*self.kin);
        // The filter's corrections stay in J's null space only through the orthogonal projector.
        let ortho;
        let jpinv = match p.joint_weights {
            None => jpinv,
            Some(_) => {
                ortho = damped_pinv_m(j, p.core.damping_threshold, p.core.damping_max).0;
                &ortho
            }
        };
        crate::safety::filter_spatial(&p.core.safety, arm, &p.spheres, kin, q, qd, j, jpinv, qdd)
    }

    #[inline]
    fn clearance(&self) -> (f64, bool) {
        let (p, arm) = (self.params, self.arm);
        if p.spheres.is_empty() {
            (f64::INFINITY, false)
        } else {
            sec::clearance(arm, &arm.capsule_segments(self.kin), &p.spheres)
        }
    }
}

impl<const N: usize> SpatialSide<'_, N> {
    /// The secondary task's value and η at this state.
    #[inline]
    fn secondary_task<const M: usize>(
        &self,
        t: f64,
        q: &VecN<N>,
        qd: &VecN<N>,
        j: &SMatrix<f64, M, N>,
    ) -> (f64, Option<VecN<N>>) {
        let (p, arm, kin) = (self.params, self.arm, &*self.kin);
        match p.core.secondary {
            Secondary::None => (0.0, None),
            Secondary::Manipulability => {
                let (w, g) = sec::manipulability(arm, kin, j);
                (w, Some(g))
            }
            Secondary::Centring => {
                let (c, g) = sec::centring(q, &p.core.safety.q_min, &p.core.safety.q_max);
                (c, Some(-g))
            }
            Secondary::Obstacles if !p.spheres.is_empty() => {
                let mut store = CapsulePoints::<N>::default();
                let links = arm.capsule_points(kin, qd, &mut store);
                let (h, g) = sec::potential(arm, &links, &p.spheres, p.weight);
                (h, Some(-g))
            }
            Secondary::Obstacles => (0.0, Some(VecN::<N>::zeros())),
            Secondary::Custom(index) => {
                let tip = [kin.p.x, kin.p.y, kin.p.z];
                super::custom_eta(index, t, q, qd, tip, &kin.jac, &p.core.safety)
            }
        }
    }
}

/// Evaluates the law at time t for state (q, q̇) with delayed velocity q̇(t − τ); `M` must be
/// the task's row count (3: position, 6: pose). `kin` is scratch.
#[inline]
pub fn evaluate<const N: usize, const M: usize>(
    params: &SpatialParams,
    arm: &SpatialArm<N>,
    t: f64,
    q: &VecN<N>,
    qd: &VecN<N>,
    qd_delayed: &VecN<N>,
    kin: &mut SpatialKinematics<N>,
) -> ControlOutput<N> {
    run::<N, M, _>(params, arm, t, (q, qd), qd_delayed, kin, Full)
}

/// [`evaluate`], or what else `out` asks for ([`super::pipeline::Output`]).
#[inline]
pub fn run<const N: usize, const M: usize, O: Output<N>>(
    params: &SpatialParams,
    arm: &SpatialArm<N>,
    t: f64,
    (q, qd): (&VecN<N>, &VecN<N>),
    qd_delayed: &VecN<N>,
    kin: &mut SpatialKinematics<N>,
    out: O,
) -> O::Value {
    let mut side = SpatialSide {
        params,
        arm,
        kin,
        eta: VecN::<N>::zeros(),
    };
    super::pipeline::run::<N, M, O>(&mut side, t, q, qd, qd_delayed, out)
}

/// With null-space damping k_d the secondary task's pull α N η − k_d q̇_N (N = I − J⁺J) is a
/// velocity servo: it drives the self-motion towards the speed v = α N η / k_d. Far from the
/// task's optimum v is large (a start near a joint limit asks several rad/s of the centring
/// spring), and the first ticks' acceleration α N η with it. The factor that caps |v| at `speed`
/// (the pull scaled as a whole, so its direction stays the gradient's) bounds both: the
/// self-motion approaches at most `speed` and is asked at most k_d · (speed + |q̇_N|). Where
/// |v| ≤ `speed` the factor is 1 and the law is the uncapped one; on the Panda's cycles v stays
/// below 1 rad/s, so the capped law's cycles and Floquet multipliers are the uncapped law's.
///
/// ```
/// use control::law::spatial::pull_scale;
/// // |α N η| = 20 rad/s², k_d = 10 /s: v = 2 rad/s, capped at 0.5 → a quarter of the pull.
/// assert_eq!(pull_scale(20.0, 10.0, 0.5), 0.25);
/// assert_eq!(pull_scale(20.0, 10.0, 4.0), 1.0); // under the cap: untouched
/// assert_eq!(pull_scale(20.0, 10.0, 0.0), 1.0); // 0: no cap
/// assert_eq!(pull_scale(20.0, 0.0, 0.5), 1.0); // no damping: no velocity to cap
/// ```
#[inline]
pub fn pull_scale(pull: f64, null_damping: f64, speed: f64) -> f64 {
    if speed <= 0.0 || null_damping <= 0.0 {
        return 1.0;
    }
    let v = pull / null_damping;
    if v > speed {
        speed / v
    } else {
        1.0
    }
}
