//! The smallest change of q̈ that meets every row a·q̈ ≥ b: null space first, then the full
//! joint space.
//!
//! For the paper's arm (n = 3, J of rank 2) the null space is the line through the unit vector
//! n̂ ⊥ both rows of J, so each row bounds one scalar s in q̈ + n̂ s and the answer is the point of
//! an interval closest to 0: one pass, no storage. Otherwise the rows are built once into a store
//! on the stack, checked there (a 7-joint arm's 28 capsule rows cost more than the QP that
//! follows, and building them twice, once to check and once to solve, made the Panda's filter
//! 1.3× slower). When a row binds, the small QP min ½|δ|² subject to G δ ≥ h is solved exactly
//! by the dual active-set method (`dual_qp`: Goldfarb–Idnani on the rows that bind, a Cholesky
//! factor of their Gram matrix); it says when the problem is infeasible, and when the rows that
//! bind are too nearly dependent to decide (rare: 0.7 % of the Panda's binding evaluations). Only
//! then, and for the paper's arm whose numbers are pinned to it, Hildreth's dual coordinate
//! ascent runs instead: each step raises one multiplier λ_j ≥ 0 and moves δ = Gᵀλ along row j,
//! with no factorisation; it converges to the exact minimiser of a feasible problem and, after
//! [`MAX_SWEEPS`] sweeps of an infeasible one, stops with the result flagged.

use super::dual_qp::{self, Outcome};
use super::Filtered;
use crate::arm::VecN;
use crate::basics::flags;
use crate::basics::MAX_JOINTS;
use crate::secondary::MAX_OBSTACLES;
use arrayvec::ArrayVec;
use nalgebra::SMatrix;

/// Most rows one problem of an N-joint arm has: every link (N of them) against every obstacle,
/// plus 2 per joint (its box), stored as this many blocks of N rows.
pub const ROW_BLOCKS: usize = MAX_OBSTACLES + 2;
/// Most rows any problem has (the largest arm).
pub const MAX_ROWS: usize = ROW_BLOCKS * MAX_JOINTS;
/// Sweeps over all rows before Hildreth's method gives up.
pub const MAX_SWEEPS: usize = 200;

/// A visitor over the rows: calls its argument with (a, b) for each a·q̈ ≥ b.
pub type Visit<'a, const N: usize> = &'a dyn Fn(&mut dyn FnMut(&VecN<N>, f64));

/// Each joint's own limits as lo_i ≤ q̈_i ≤ hi_i (`rows::joint_box`).
pub type JointBox<'a> = (&'a [f64; MAX_JOINTS], &'a [f64; MAX_JOINTS]);

/// A row counts as violated when it misses by more than this (relative to 1 + |b|).
const TOL: f64 = 1e-9;

#[inline]
fn tol(b: f64) -> f64 {
    TOL * (1.0 + b.abs())
}

/// Whether a row a·q̈ ≥ b is missed, given a·q̈.
#[inline(always)]
pub fn misses(b: f64, a_qdd: f64) -> bool {
    b - a_qdd > tol(b)
}

/// Whether q̈ leaves a joint's box, judged as the box's rows are.
pub fn box_missed<const N: usize>(joint_box: JointBox<'_>, qdd: &VecN<N>) -> bool {
    (0..N).any(|i| {
        let (lo, hi) = (joint_box.0[i], joint_box.1[i]);
        (lo.is_finite() && misses(lo, qdd[i])) || (hi.is_finite() && misses(-hi, -qdd[i]))
    })
}

/// The unit vector spanning J's null space for n = 3 and a 2-row task (None if J has rank < 2,
/// n ≠ 3 or m ≠ 2).
pub fn null_vector<const N: usize, const M: usize>(j: &SMatrix<f64, M, N>) -> Option<VecN<N>> {
    if N != 3 || M != 2 {
        return None;
    }
    let r = |c: usize, k: usize| j[(c, k)];
    let v = VecN::<N>::from_fn(|i, _| {
        let (a, b) = ((i + 1) % 3, (i + 2) % 3);
        r(0, a) * r(1, b) - r(0, b) * r(1, a)
    });
    let n = v.norm();
    (n > 1e-9).then(|| v / n)
}

/// Solves for the filtered q̈ (see the module doc), then clamps to the acceleration limits.
pub fn smallest_change<const N: usize, const M: usize>(
    visit: Visit<'_, N>,
    joint_box: JointBox<'_>,
    j: &SMatrix<f64, M, N>,
    jpinv: &SMatrix<f64, N, M>,
    qdd: &VecN<N>,
    qdd_max: &[f64; MAX_JOINTS],
) -> Filtered<N> {
    match null_vector(j) {
        Some(n) => on_the_line(&n, visit, joint_box, qdd, qdd_max),
        None => in_stored_rows(visit, joint_box, j, jpinv, qdd, qdd_max),
    }
}

/// A one-dimensional null space: each row bounds s in q̈ + n̂ s, one pass with no storage; the
/// rows are stored only when the line cannot meet them all.
fn on_the_line<const N: usize>(
    n: &VecN<N>,
    visit: Visit<'_, N>,
    joint_box: JointBox<'_>,
    qdd: &VecN<N>,
    qdd_max: &[f64; MAX_JOINTS],
) -> Filtered<N> {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    let (mut violated, mut line_ok) = (false, true);
    let mut bound_s = |r: f64, bad: bool, al: f64, small: f64| {
        violated |= bad;
        if al.abs() <= small {
            line_ok &= !bad;
        } else if al > 0.0 {
            lo = lo.max(r / al);
        } else {
            hi = hi.min(r / al);
        }
    };
    visit(&mut |a, b| {
        let r = b - a.dot(qdd);
        bound_s(r, r > tol(b), a.dot(n), 1e-12 * a.norm());
    });
    let (lo_box, hi_box) = joint_box;
    for i in 0..N {
        // lo ≤ q̈_i + n_i s ≤ hi, two rows on one axis.
        for (bound, sign) in [(lo_box[i], 1.0), (hi_box[i], -1.0)] {
            if bound.is_finite() {
                let r = sign * (bound - qdd[i]);
                bound_s(r, r > tol(bound), sign * n[i], 1e-12);
            }
        }
    }
    if !violated {
        return Filtered::unchanged(qdd);
    }
    if line_ok && lo <= hi + 1e-12 * (1.0 + lo.abs()) {
        return clamped(
            qdd + n * 0.0f64.clamp(lo, hi.max(lo)),
            qdd_max,
            flags::SAFETY_ACTIVE,
        );
    }
    // The interval was exact for the line: off it, the full joint space.
    let mut rows = Rows::<N>::empty();
    rows.collect(visit, joint_box, qdd);
    full_space::<N, 2>(&mut rows, qdd, qdd_max, flags::SAFETY_ACTIVE)
}

/// Any other null space: the rows are built once, stored, checked there and solved null space
/// first.
fn in_stored_rows<const N: usize, const M: usize>(
    visit: Visit<'_, N>,
    joint_box: JointBox<'_>,
    j: &SMatrix<f64, M, N>,
    jpinv: &SMatrix<f64, N, M>,
    qdd: &VecN<N>,
    qdd_max: &[f64; MAX_JOINTS],
) -> Filtered<N> {
    let mut rows = Rows::<N>::empty();
    if !rows.collect(visit, joint_box, qdd) {
        return Filtered::unchanged(qdd);
    }
    match rows.null_space(j, jpinv) {
        Some(d) => clamped(qdd + d, qdd_max, flags::SAFETY_ACTIVE),
        None => full_space::<N, M>(&mut rows, qdd, qdd_max, flags::SAFETY_ACTIVE),
    }
}

/// The rows solved in the full joint space, flagged so.
fn full_space<const N: usize, const M: usize>(
    rows: &mut Rows<N>,
    qdd: &VecN<N>,
    qdd_max: &[f64; MAX_JOINTS],
    flag: u32,
) -> Filtered<N> {
    let mut flag = flag | flags::SAFETY_LEFT_NULL_SPACE;
    let (d, ok) = rows.full_space::<M>();
    if !ok {
        flag |= flags::SAFETY_INFEASIBLE;
    }
    clamped(qdd + d, qdd_max, flag)
}

/// `out` held within the acceleration limits.
fn clamped<const N: usize>(
    mut out: VecN<N>,
    qdd_max: &[f64; MAX_JOINTS],
    flag: u32,
) -> Filtered<N> {
    for i in 0..N {
        out[i] = out[i].clamp(-qdd_max[i], qdd_max[i]);
    }
    Filtered {
        qdd: out,
        flags: flag,
    }
}

/// Rows a·δ ≥ b − a·q̈_nom, stored on the stack for the QP.
///
/// The stores have the largest arm's capacity but are not initialised past the rows they hold
/// (`ArrayVec`): an arm takes at most [`ROW_BLOCKS`] blocks of its own N rows, and an empty store
/// costs nothing to make. Zeroed arrays sized by the arm cost the Panda's binding filter two
/// 126-row memsets (8 KB each) per evaluation; sized by the largest arm, about a microsecond.
struct Rows<const N: usize> {
    a: ArrayVec<VecN<N>, MAX_ROWS>,
    h: ArrayVec<f64, MAX_ROWS>,
}

impl<const N: usize> Rows<N> {
    fn empty() -> Self {
        Self {
            a: ArrayVec::new(),
            h: ArrayVec::new(),
        }
    }

    /// The rows held.
    fn a(&self) -> &[VecN<N>] {
        &self.a
    }

    fn h(&self) -> &[f64] {
        &self.h
    }

    fn push(&mut self, a: VecN<N>, h: f64) {
        if self.a.len() < ROW_BLOCKS * N {
            self.a.push(a);
            self.h.push(h);
        }
    }

    /// Stores the rows; true if q̈ misses any of them.
    fn collect(&mut self, visit: Visit<'_, N>, joint_box: JointBox<'_>, qdd: &VecN<N>) -> bool {
        let r = self;
        let mut violated = false;
        let mut push = |a: &VecN<N>, b: f64| {
            let a_qdd = a.dot(qdd);
            violated |= misses(b, a_qdd);
            r.push(*a, b - a_qdd);
        };
        visit(&mut push);
        for i in 0..N {
            let e = VecN::<N>::from_fn(|k, _| if k == i { 1.0 } else { 0.0 });
            if joint_box.0[i].is_finite() {
                push(&e, joint_box.0[i]);
            }
            if joint_box.1[i].is_finite() {
                push(&-e, -joint_box.1[i]);
            }
        }
        violated
    }

    /// The smallest δ = N z that meets every row, if the null space can.
    fn null_space<const M: usize>(
        &mut self,
        j: &SMatrix<f64, M, N>,
        jpinv: &SMatrix<f64, N, M>,
    ) -> Option<VecN<N>> {
        if N <= M {
            return None;
        }
        let mut projected = Self::empty();
        for (a, &h) in self.a().iter().zip(self.h()) {
            projected.push(a - j.transpose() * (jpinv.transpose() * a), h);
        }
        if M != 2 {
            match dual_qp::solve(projected.a(), projected.h()) {
                Outcome::Solved(d) => return Some(d),
                Outcome::Infeasible => return None,
                Outcome::Undecided => {}
            }
        }
        let (d, ok) = projected.hildreth();
        ok.then_some(d)
    }

    /// The smallest δ in the full joint space; `false` if no δ meets every row. Spatial tasks
    /// (m ≠ 2) try the exact dual active-set method first; the planar arm keeps Hildreth's
    /// iterates, to which its published numbers are pinned.
    fn full_space<const M: usize>(&mut self) -> (VecN<N>, bool) {
        if M != 2 {
            match dual_qp::solve(self.a(), self.h()) {
                Outcome::Solved(d) => return (d, true),
                Outcome::Infeasible | Outcome::Undecided => {}
            }
        }
        self.hildreth()
    }

    /// min ½|δ|² subject to a_j·δ ≥ h_j, by dual coordinate ascent.
    fn hildreth(&self) -> (VecN<N>, bool) {
        let (rows, hs) = (self.a(), self.h());
        let mut lambda_store = [[0.0f64; N]; ROW_BLOCKS];
        let lambda = lambda_store.as_flattened_mut();
        let mut d = VecN::<N>::zeros();
        for _ in 0..MAX_SWEEPS {
            let mut moved = 0.0f64;
            for k in 0..rows.len() {
                let a = &rows[k];
                let aa = a.norm_squared();
                if aa < 1e-24 {
                    continue;
                }
                let next = (lambda[k] + (hs[k] - a.dot(&d)) / aa).max(0.0);
                let step = next - lambda[k];
                if step != 0.0 {
                    d += a * step;
                    lambda[k] = next;
                    moved = moved.max(step.abs() * aa.sqrt());
                }
            }
            if moved <= 1e-12 * (1.0 + d.norm()) {
                break;
            }
        }
        let ok = (rows.iter().zip(hs)).all(|(a, &h)| a.dot(&d) >= h - 1e-7 * (1.0 + h.abs()));
        (d, ok)
    }
}
