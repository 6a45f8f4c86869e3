//! A URDF chain as the control law sees it: a tool point on the tip, link capsules for the
//! obstacles, and the motion of any point of any link.
//!
//! The law needs more than [`Model::tip_kinematics`]: the secondary tasks and the safety filter
//! need the position, Jacobian, velocity and drift (J̇q̇) of points along every link. One forward
//! pass stores, for each body, its origin, axis, angular velocity, angular acceleration and
//! origin acceleration at q̈ = 0; any point's motion then follows in O(n) without another pass.

use super::point::Links;
use crate::basics::MAX_JOINTS;
use crate::model::{Frames, Model};
use nalgebra::Vector3;

type Vec3 = Vector3<f64>;
use nalgebra::{Matrix3, SMatrix, SVector, Vector6};

pub type VecN<const N: usize> = SVector<f64, N>;
/// Rows of a point's Jacobian: ṗ = J q̇.
pub type Jac3<const N: usize> = SMatrix<f64, 3, N>;

/// The chain, the tool point and the link capsules.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialArm<const N: usize> {
    pub model: Model<N>,
    /// The tool point in the tip frame (the zero vector: the tip link's origin).
    pub tool: Vec3,
    /// Capsule radius of link j, the segment from joint j's origin to joint j+1's (the last
    /// one to the tool point), or between [`Self::ends`]; 0 for a bare segment.
    pub radii: [f64; N],
    /// Link j's capsule ends in body j's frame, where they are the capsule's own
    /// (`robot.capsules`: a capsule fitted to the link's housing rather than strung between
    /// joint origins); None: the joint origins.
    pub ends: Option<[[Vec3; 2]; N]>,
}

/// Storage for the capsules' end points ([`SpatialArm::capsule_points`]): N + 1 about the joint
/// origins, two rows of N with ends of their own. It starts as the chain; the second row is
/// made (and zeroed) only for an arm whose capsules have ends of their own.
#[derive(Clone, Copy)]
pub enum CapsulePoints<const N: usize> {
    Chain(Points<N>),
    Pairs(Points<N>, Points<N>),
}

impl<const N: usize> Default for CapsulePoints<N> {
    fn default() -> Self {
        Self::Chain([PointMotion::default(); MAX_JOINTS + 1])
    }
}

/// Each link's capsule segment (base frame), [`SpatialArm::capsule_segments`].
pub type Segments = [[Vec3; 2]; MAX_JOINTS];

/// Kinematics at one state, in the base frame.
#[derive(Clone, Copy, Debug)]
pub struct SpatialKinematics<const N: usize> {
    pub frames: Frames<N>,
    /// The tool point and the tip's orientation.
    pub p: Vec3,
    pub rot: Matrix3<f64>,
    /// 6×N at the tool point: rows v then ω.
    pub jac: SMatrix<f64, 6, N>,
    /// The tool point's classical acceleration and the angular one at q̈ = 0.
    pub jdot_qd: Vector6<f64>,
    /// Per body: angular velocity, angular acceleration and origin acceleration at q̈ = 0.
    pub w: [Vec3; N],
    pub wd: [Vec3; N],
    pub acc: [Vec3; N],
}

impl<const N: usize> Default for SpatialKinematics<N> {
    fn default() -> Self {
        Self {
            frames: Frames::default(),
            p: Vec3::zeros(),
            rot: Matrix3::identity(),
            jac: SMatrix::zeros(),
            jdot_qd: Vector6::zeros(),
            w: [Vec3::zeros(); N],
            wd: [Vec3::zeros(); N],
            acc: [Vec3::zeros(); N],
        }
    }
}

/// Position, Jacobian, velocity and drift (J̇q̇) of one point of the arm.
pub type PointMotion<const N: usize> = super::point::PointMotion<N, 3>;

/// The capsule end points P_0 … P_N (joint origins, then the tool point).
pub type Points<const N: usize> = super::point::Points<N, 3>;

impl<const N: usize> SpatialKinematics<N> {
    /// Joint i's axis and origin in the base frame.
    #[inline(always)]
    pub fn axis(&self, i: usize) -> Vec3 {
        self.frames.body[i].rot.column(2).into_owned()
    }
    #[inline(always)]
    pub fn origin(&self, i: usize) -> Vec3 {
        self.frames.body[i].pos
    }
}

impl<const N: usize> SpatialArm<N> {
    /// A bare chain: the tool at the tip link's origin, no capsule radii.
    pub fn new(model: Model<N>) -> Self {
        Self {
            model,
            tool: Vec3::zeros(),
            radii: [0.0; N],
            ends: None,
        }
    }

    /// One forward pass: frames, tool pose, 6×N Jacobian, J̇q̇ and every body's motion.
    ///
    /// ```
    /// # use control::model::{builtin, Chain};
    /// # use control::arm::spatial::{SpatialArm, SpatialKinematics};
    /// # use nalgebra::SVector;
    /// let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    /// let arm = SpatialArm::new(chain.model::<7>().unwrap());
    /// let mut k = SpatialKinematics::default();
    /// arm.kinematics(&SVector::zeros(), &SVector::zeros(), &mut k);
    /// assert!((k.p.z - (0.333 + 0.316 + 0.384 - 0.107)).abs() < 1e-12); // flange points down
    /// ```
    #[inline]
    pub fn kinematics(&self, q: &VecN<N>, qd: &VecN<N>, out: &mut SpatialKinematics<N>) {
        self.model.frames(q, &mut out.frames);
        let tip = out.frames.tip;
        out.rot = tip.rot;
        let p = tip.pos + tip.rot * self.tool;
        out.p = p;
        let (mut w, mut wd, mut acc) = (Vec3::zeros(), Vec3::zeros(), Vec3::zeros());
        let mut o_prev = Vec3::zeros();
        for i in 0..N {
            let (z, o) = (out.axis(i), out.origin(i));
            let r = o - o_prev;
            acc += wd.cross(&r) + w.cross(&w.cross(&r));
            if self.model.prismatic[i] {
                acc += w.cross(&z) * (2.0 * qd[i]);
                out.jac.fixed_view_mut::<3, 1>(0, i).copy_from(&z);
                out.jac.fixed_view_mut::<3, 1>(3, i).fill(0.0);
            } else {
                wd += w.cross(&z) * qd[i];
                w += z * qd[i];
                let col = z.cross(&(p - o));
                out.jac.fixed_view_mut::<3, 1>(0, i).copy_from(&col);
                out.jac.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
            }
            (out.w[i], out.wd[i], out.acc[i]) = (w, wd, acc);
            o_prev = o;
        }
        let r = p - o_prev;
        let a = acc + wd.cross(&r) + w.cross(&w.cross(&r));
        out.jdot_qd = Vector6::new(a.x, a.y, a.z, wd.x, wd.y, wd.z);
    }

    /// Where the tool point is at `q` (base frame): the measured arm's, when the law runs on a
    /// reference.
    pub fn tool_position(&self, q: &VecN<N>) -> Vec3 {
        let mut frames = Frames::<N>::default();
        self.model.frames(q, &mut frames);
        frames.tip.pos + frames.tip.rot * self.tool
    }

    /// The motion of point `x` (base frame) fixed to body `body`.
    #[inline]
    pub fn point_motion(
        &self,
        kin: &SpatialKinematics<N>,
        body: usize,
        x: Vec3,
        qd: &VecN<N>,
    ) -> PointMotion<N> {
        let mut out = PointMotion::default();
        self.point_motion_into(kin, body, x, qd, &mut out);
        out
    }

    /// [`Self::point_motion`] written in place: a 7-joint point is 30 numbers, and returning
    /// eight of them by value per law evaluation was 7 % of the Panda's tick in copies.
    #[inline]
    pub fn point_motion_into(
        &self,
        kin: &SpatialKinematics<N>,
        body: usize,
        x: Vec3,
        qd: &VecN<N>,
        out: &mut PointMotion<N>,
    ) {
        out.jac.fill(0.0);
        for k in 0..=body {
            let z = kin.axis(k);
            let col = if self.model.prismatic[k] {
                z
            } else {
                z.cross(&(x - kin.origin(k)))
            };
            out.jac.set_column(k, &col);
        }
        let r = x - kin.origin(body);
        let (w, wd) = (kin.w[body], kin.wd[body]);
        out.pos = x;
        out.vel = out.jac * qd;
        out.drift = kin.acc[body] + wd.cross(&r) + w.cross(&w.cross(&r));
    }

    /// The motion of every capsule's ends, in `out`, and the view that pairs them per link:
    /// about the joint origins, P_0 … P_{N−1} (P_j on body j) and P_N (the tool point), link j
    /// from P_j to P_{j+1}; with [`Self::ends`], link j's own two ends on body j.
    pub fn capsule_points<'a>(
        &self,
        kin: &SpatialKinematics<N>,
        qd: &VecN<N>,
        out: &'a mut CapsulePoints<N>,
    ) -> Links<'a, N, 3> {
        match &self.ends {
            None => {
                if !matches!(out, CapsulePoints::Chain(_)) {
                    *out = CapsulePoints::default();
                }
                let CapsulePoints::Chain(points) = out else {
                    unreachable!("made a chain above")
                };
                for j in 0..N {
                    // Joint j's origin does not move with q_j (revolute), so it is a point of
                    // body j−1; on body j it has the same motion and Jacobian columns 0..j−1
                    // (column j is zero).
                    self.point_motion_into(kin, j, kin.origin(j), qd, &mut points[j]);
                }
                self.point_motion_into(kin, N - 1, kin.p, qd, &mut points[N]);
                Links::chain(points)
            }
            Some(ends) => {
                if !matches!(out, CapsulePoints::Pairs(..)) {
                    let zero = [PointMotion::default(); MAX_JOINTS + 1];
                    *out = CapsulePoints::Pairs(zero, zero);
                }
                let CapsulePoints::Pairs(first, second) = out else {
                    unreachable!("made pairs above")
                };
                for (j, [a, b]) in ends.iter().enumerate() {
                    let body = &kin.frames.body[j];
                    self.point_motion_into(kin, j, body.apply(a), qd, &mut first[j]);
                    self.point_motion_into(kin, j, body.apply(b), qd, &mut second[j]);
                }
                Links::pairs(first, second)
            }
        }
    }

    /// Each link's capsule segment without its motion (clearance, planning, drawing).
    pub fn capsule_segments(&self, kin: &SpatialKinematics<N>) -> Segments {
        let mut out = [[Vec3::zeros(); 2]; MAX_JOINTS];
        match &self.ends {
            None => {
                for (j, seg) in out.iter_mut().enumerate().take(N) {
                    let b = if j + 1 < N { kin.origin(j + 1) } else { kin.p };
                    *seg = [kin.origin(j), b];
                }
            }
            Some(ends) => {
                for (j, [a, b]) in ends.iter().enumerate() {
                    let body = &kin.frames.body[j];
                    out[j] = [body.apply(a), body.apply(b)];
                }
            }
        }
        out
    }
}
