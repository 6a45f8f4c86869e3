//! Properties every rigid-body model must have, over random states, on the Panda and on a chain
//! with every joint kind (prismatic, turned axes, a tilted base): M symmetric positive definite
//! and equal to RNEA's columns, ABA inverting RNEA, the Jacobian and J̇q̇ against finite
//! differences, energy conserved by a free chain; and the planar chain equal to the closed form.

use control::arm::{FixedArm, Kinematics};
use control::model::{builtin, Chain, Model, TipKinematics};
use nalgebra::{Matrix3, SVector, Vector3};
use proptest::prelude::*;

fn panda() -> Model<7> {
    Chain::from_urdf(builtin("panda").unwrap(), None, None)
        .unwrap()
        .model()
        .unwrap()
}

fn quirks() -> Model<6> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/urdf/quirks.urdf"
    );
    Chain::from_urdf(
        &std::fs::read_to_string(path).unwrap(),
        Some("base"),
        Some("tcp"),
    )
    .unwrap()
    .model()
    .unwrap()
}

fn vec<const N: usize>(r: f64) -> impl Strategy<Value = SVector<f64, N>> {
    prop::collection::vec(-r..r, N).prop_map(|v| SVector::<f64, N>::from_column_slice(&v))
}

fn tip<const N: usize>(
    m: &Model<N>,
    q: &SVector<f64, N>,
    qd: &SVector<f64, N>,
) -> TipKinematics<N> {
    let mut k = TipKinematics::default();
    m.tip_kinematics(q, qd, &mut k);
    k
}

fn vee(s: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(
        s[(2, 1)] - s[(1, 2)],
        s[(0, 2)] - s[(2, 0)],
        s[(1, 0)] - s[(0, 1)],
    ) * 0.5
}

fn check_dynamics<const N: usize>(
    m: &Model<N>,
    q: SVector<f64, N>,
    qd: SVector<f64, N>,
    qdd: SVector<f64, N>,
) {
    let mm = m.mass_matrix(&q);
    assert!((mm - mm.transpose()).norm() <= 1e-12 * mm.norm());
    assert!(mm.cholesky().is_some(), "M not positive definite");
    let g = m.gravity_torques(&q);
    for i in 0..N {
        let mut e = SVector::<f64, N>::zeros();
        e[i] = 1.0;
        let col = m.rnea(&q, &SVector::zeros(), &e) - g;
        assert!((col - mm.column(i)).norm() < 1e-10 * mm.norm().max(1.0));
    }
    let tau = m.rnea(&q, &qd, &qdd);
    let back = m.aba(&q, &qd, &tau);
    assert!(
        (back - qdd).norm() < 1e-9 * qdd.norm().max(1.0),
        "ABA(RNEA(q̈)) = {back} ≠ {qdd}"
    );
}

fn check_derivatives<const N: usize>(m: &Model<N>, q: SVector<f64, N>, qd: SVector<f64, N>) {
    const H: f64 = 1e-6;
    let k = tip(m, &q, &qd);
    for i in 0..N {
        let mut e = SVector::<f64, N>::zeros();
        e[i] = H;
        let (a, b) = (tip(m, &(q + e), &qd), tip(m, &(q - e), &qd));
        let v = (a.frames.tip.pos - b.frames.tip.pos) / (2.0 * H);
        let w = vee(
            &((a.frames.tip.rot - b.frames.tip.rot) / (2.0 * H) * k.frames.tip.rot.transpose())
        );
        assert!(
            (v - k.jacobian.fixed_view::<3, 1>(0, i)).norm() < 1e-7,
            "linear column {i}"
        );
        assert!(
            (w - k.jacobian.fixed_view::<3, 1>(3, i)).norm() < 1e-7,
            "angular column {i}"
        );
    }
    // At q̈ = 0, d/dt (J q̇) along q + t q̇.
    let (a, b) = (tip(m, &(q + qd * H), &qd), tip(m, &(q - qd * H), &qd));
    let fd = (a.jacobian * qd - b.jacobian * qd) / (2.0 * H);
    assert!(
        (fd - k.jdot_qd).norm() < 1e-6 * fd.norm().max(1.0),
        "J̇q̇ {} vs {fd}",
        k.jdot_qd
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn panda_dynamics_are_consistent(q in vec::<7>(2.5), qd in vec::<7>(2.0), qdd in vec::<7>(5.0)) {
        check_dynamics(&panda(), q, qd, qdd);
    }

    #[test]
    fn every_joint_kind_dynamics_are_consistent(q in vec::<6>(1.0), qd in vec::<6>(2.0), qdd in vec::<6>(5.0)) {
        check_dynamics(&quirks(), q, qd, qdd);
    }

    #[test]
    fn panda_jacobian_and_jdot_qd_match_finite_differences(q in vec::<7>(2.5), qd in vec::<7>(2.0)) {
        check_derivatives(&panda(), q, qd);
    }

    #[test]
    fn every_joint_kind_jacobian_matches_finite_differences(q in vec::<6>(1.0), qd in vec::<6>(2.0)) {
        check_derivatives(&quirks(), q, qd);
    }

    #[test]
    fn planar_chain_is_the_closed_form(q in vec::<3>(3.0), qd in vec::<3>(5.0)) {
        let chain = Chain::from_urdf(builtin("planar3").unwrap(), None, None).unwrap();
        let k = tip(&chain.model::<3>().unwrap(), &q, &qd);
        let mut closed = Kinematics::default();
        FixedArm::new([1.0, 1.0, 1.0]).kinematics(&q, &qd, &mut closed);
        prop_assert!((k.frames.tip.pos.xy() - closed.p).norm() < 1e-12);
        prop_assert!(k.frames.tip.pos.z.abs() < 1e-12);
        prop_assert!((k.jacobian.fixed_rows::<2>(0) - closed.j).norm() < 1e-12);
        prop_assert!((k.jdot_qd.fixed_rows::<2>(0) - closed.jdot_qd).norm() < 1e-12);
        for i in 0..3 {
            prop_assert!((k.frames.body[i].pos.xy() - closed.points[i]).norm() < 1e-12);
        }
    }
}

/// ½ q̇ᵀ M q̇ of a chain moving freely without gravity stays put under RK4 over 10 s at 1 ms.
fn energy_drift<const N: usize>(
    mut m: Model<N>,
    mut q: SVector<f64, N>,
    mut qd: SVector<f64, N>,
) -> f64 {
    m.gravity = Vector3::zeros();
    let zero = SVector::<f64, N>::zeros();
    let energy = |q: &SVector<f64, N>, qd: &SVector<f64, N>| 0.5 * qd.dot(&(m.mass_matrix(q) * qd));
    let e0 = energy(&q, &qd);
    let dt = 1e-3;
    let f = |q: &SVector<f64, N>, qd: &SVector<f64, N>| (*qd, m.aba(q, qd, &zero));
    for _ in 0..10_000 {
        let (k1q, k1v) = f(&q, &qd);
        let (k2q, k2v) = f(&(q + k1q * (dt / 2.0)), &(qd + k1v * (dt / 2.0)));
        let (k3q, k3v) = f(&(q + k2q * (dt / 2.0)), &(qd + k2v * (dt / 2.0)));
        let (k4q, k4v) = f(&(q + k3q * dt), &(qd + k3v * dt));
        q += (k1q + k2q * 2.0 + k3q * 2.0 + k4q) * (dt / 6.0);
        qd += (k1v + k2v * 2.0 + k3v * 2.0 + k4v) * (dt / 6.0);
    }
    (energy(&q, &qd) - e0).abs() / e0
}

#[test]
fn a_free_panda_conserves_energy() {
    let q = SVector::from([0.1, -0.3, 0.2, -1.8, 0.1, 1.5, 0.3]);
    let qd = SVector::from([0.5, -0.4, 0.8, 0.3, -1.0, 0.6, 1.2]);
    let drift = energy_drift(panda(), q, qd);
    assert!(drift < 1e-6, "relative energy drift {drift:.2e}");
}

#[test]
fn a_free_chain_with_prismatic_joints_conserves_energy() {
    let q = SVector::from([0.2, 0.05, -0.4, 0.3, 0.02, 0.5]);
    let qd = SVector::from([0.6, 0.1, -0.9, 0.4, -0.05, 1.0]);
    let drift = energy_drift(quirks(), q, qd);
    assert!(drift < 1e-6, "relative energy drift {drift:.2e}");
}
