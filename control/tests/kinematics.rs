//! Property tests: every analytic derivative against central finite differences, over random
//! configurations, for both arm models.

use control::arm::{ArmModel, FixedArm, FloatingArm, Kinematics, Vec2, VecN};
use control::secondary::{potential, Obstacle, ObstacleSet, PotentialWeights};
use proptest::prelude::*;

const H: f64 = 1e-6;

fn fixed() -> ArmModel<3> {
    ArmModel::Fixed(FixedArm::new([1.0, 0.8, 1.2]))
}

fn floating() -> ArmModel<3> {
    ArmModel::Floating(FloatingArm {
        links: [1.0, 1.0, 1.0],
        link_masses: [1.0, 1.5, 0.7],
        link_inertias: [0.3, 0.2, 0.1],
        base_mass: 5.0,
        base_inertia: 3.0,
        base_offset: 1.0,
    })
}

fn kin(m: &ArmModel<3>, phi: f64, q: &VecN<3>, qd: &VecN<3>) -> Kinematics<3> {
    let mut k = Kinematics::default();
    m.kinematics(phi, q, qd, &mut k);
    k
}

fn vec3() -> impl Strategy<Value = VecN<3>> {
    prop::array::uniform3(-3.0f64..3.0).prop_map(VecN::<3>::from)
}

/// Integrates the floating model's φ̇ = k(q)·q̇ along a short path q(s) = q + s q̇ with RK4
/// at high resolution: the end-effector trajectory then gives ṗ and p̈ by differences.
fn floating_path(
    m: &ArmModel<3>,
    phi0: f64,
    q: &VecN<3>,
    qd: &VecN<3>,
    qdd: &VecN<3>,
    t: f64,
) -> (f64, VecN<3>) {
    let ArmModel::Floating(a) = m else {
        unreachable!()
    };
    let steps = 200;
    let h = t / steps as f64;
    let mut phi = phi0;
    let path = |s: f64| (q + qd * s + qdd * (0.5 * s * s), qd + qdd * s);
    for i in 0..steps {
        let s = i as f64 * h;
        let f = |s: f64| {
            let (qq, vv) = path(s);
            a.base_rate(&qq, &vv)
        };
        let k1 = f(s);
        let k2 = f(s + 0.5 * h);
        let k4 = f(s + h);
        phi += h / 6.0 * (k1 + 4.0 * k2 + k4);
    }
    (phi, path(t).0)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn fixed_jacobian_matches_fd(q in vec3(), qd in vec3()) {
        let m = fixed();
        let k0 = kin(&m, 0.0, &q, &qd);
        for i in 0..3 {
            let mut e = VecN::<3>::zeros(); e[i] = H;
            let d = (kin(&m, 0.0, &(q + e), &qd).p - kin(&m, 0.0, &(q - e), &qd).p) / (2.0 * H);
            prop_assert!((d - k0.j.column(i)).norm() < 1e-7);
            for j in 0..3 {
                let dj = (kin(&m, 0.0, &(q + e), &qd).points[j] - kin(&m, 0.0, &(q - e), &qd).points[j]) / (2.0 * H);
                prop_assert!((dj - k0.point_jac[j].column(i)).norm() < 1e-7);
            }
        }
        // J̇q̇ = d/ds [J(q + s q̇)] q̇
        let jp = kin(&m, 0.0, &(q + qd * H), &qd).j;
        let jm = kin(&m, 0.0, &(q - qd * H), &qd).j;
        let fd = (jp - jm) / (2.0 * H) * qd;
        prop_assert!((fd - k0.jdot_qd).norm() < 1e-6 * (1.0 + qd.norm_squared()));
    }

    #[test]
    fn manipulability_gradient_matches_fd(q in vec3(), floating_model in any::<bool>()) {
        let m = if floating_model { floating() } else { fixed() };
        let z = VecN::<3>::zeros();
        let k0 = kin(&m, 0.4, &q, &z);
        let (w0, g) = m.manipulability(&q, &k0);
        prop_assume!(w0 > 1e-3);
        for i in 0..3 {
            let mut e = VecN::<3>::zeros(); e[i] = H;
            let (wp, _) = m.manipulability(&(q + e), &kin(&m, 0.4, &(q + e), &z));
            let (wm, _) = m.manipulability(&(q - e), &kin(&m, 0.4, &(q - e), &z));
            prop_assert!(((wp - wm) / (2.0 * H) - g[i]).abs() < 1e-6, "i={} fd={} an={}", i, (wp-wm)/(2.0*H), g[i]);
        }
    }

    #[test]
    fn potential_gradient_matches_fd(q in vec3(), ox in -1.5f64..2.5, oy in -1.5f64..2.5, floating_model in any::<bool>()) {
        let m = if floating_model { floating() } else { fixed() };
        let mut obs = ObstacleSet::new();
        obs.push(Obstacle { center: Vec2::new(ox, oy), radius: 0.6, margin: 0.3 }).unwrap();
        obs.push(Obstacle { center: Vec2::new(oy, ox), radius: 0.4, margin: 0.1 }).unwrap();
        let w = PotentialWeights { w1: 2.0, w2: 3.0 };
        let z = VecN::<3>::zeros();
        let (_, g) = potential(&kin(&m, 0.2, &q, &z), &obs, w);
        for i in 0..3 {
            let mut e = VecN::<3>::zeros(); e[i] = H;
            let (hp, _) = potential(&kin(&m, 0.2, &(q + e), &z), &obs, w);
            let (hm, _) = potential(&kin(&m, 0.2, &(q - e), &z), &obs, w);
            let fd = (hp - hm) / (2.0 * H);
            // The link terms switch on and off where the perpendicular's foot leaves the link,
            // so h jumps there (by ½w·e², small near the zone's edge): a difference straddling
            // the jump is not a derivative. A smooth h gives the same difference at half the
            // step (to O(H²)); a jump J gives J/2H more at one of the two, so those rare points
            // are set aside by comparing them, whatever the size of the jump.
            let (hp2, _) = potential(&kin(&m, 0.2, &(q + e / 2.0), &z), &obs, w);
            let (hm2, _) = potential(&kin(&m, 0.2, &(q - e / 2.0), &z), &obs, w);
            let fd_half = (hp2 - hm2) / H;
            prop_assume!((fd - fd_half).abs() < 1e-6);
            prop_assert!((fd - g[i]).abs() < 1e-5, "i={} fd={} an={}", i, fd, g[i]);
        }
    }

    #[test]
    fn floating_generalized_jacobian_matches_momentum_path(q in vec3(), qd in vec3(), qdd in vec3(), phi in -3.0f64..3.0) {
        let m = floating();
        let ArmModel::Floating(a) = m else { unreachable!() };
        // p(s) along the trajectory with φ from angular momentum conservation.
        let p_at = |s: f64| {
            let (ph, qq) = floating_path(&m, phi, &q, &qd, &qdd, s);
            kin(&m, ph, &qq, &qd).p
        };
        let h = 1e-4;
        let (pm, p0, pp) = (p_at(-h), p_at(0.0), p_at(h));
        let v_fd = (pp - pm) / (2.0 * h);
        let a_fd = (pp - p0 * 2.0 + pm) / (h * h);
        let k0 = kin(&m, phi, &q, &qd);
        prop_assert!((v_fd - k0.j * qd).norm() < 1e-6 * (1.0 + qd.norm()), "v {} vs {}", v_fd, k0.j * qd);
        let acc = k0.j * qdd + k0.jdot_qd;
        prop_assert!((a_fd - acc).norm() < 2e-4 * (1.0 + qd.norm_squared() + qdd.norm()), "a {} vs {}", a_fd, acc);
        // φ̇ agrees with the kinematics' report.
        prop_assert!((a.base_rate(&q, &qd) - k0.base_rate).abs() < 1e-12);
    }

    #[test]
    fn floating_momentum_is_conserved(q in vec3(), qd in vec3(), phi in -3.0f64..3.0) {
        // Total linear momentum is zero and the centre of mass stays at the origin, and total
        // angular momentum about it is zero, computed body by body by finite differences.
        let m = floating();
        let ArmModel::Floating(a) = m else { unreachable!() };
        let bodies = |s: f64| {
            let (ph, qq) = floating_path(&m, phi, &q, &qd, &VecN::<3>::zeros(), s);
            let k = kin(&m, ph, &qq, &qd);
            let base = a.base_position(ph, &qq);
            let mut com = [Vec2::zeros(); 4];
            let mut ang = [0.0; 4];
            com[0] = base; ang[0] = ph;
            let mut th = ph;
            for j in 0..3 {
                let end = if j < 2 { k.points[j + 1] } else { k.p };
                com[j + 1] = (k.points[j] + end) * 0.5;
                th += qq[j];
                ang[j + 1] = th;
            }
            (com, ang)
        };
        let h = 1e-5;
        let (c0, a0) = bodies(0.0);
        let (cp, ap) = bodies(h);
        let (cm, am) = bodies(-h);
        let masses = [a.base_mass, a.link_masses[0], a.link_masses[1], a.link_masses[2]];
        let inertias = [a.base_inertia, a.link_inertias[0], a.link_inertias[1], a.link_inertias[2]];
        let mut lin = Vec2::zeros();
        let mut cm_pos = Vec2::zeros();
        let mut l = 0.0;
        for b in 0..4 {
            let v = (cp[b] - cm[b]) / (2.0 * h);
            let w = (ap[b] - am[b]) / (2.0 * h);
            lin += v * masses[b];
            cm_pos += c0[b] * masses[b];
            l += inertias[b] * w + masses[b] * (c0[b].x * v.y - c0[b].y * v.x);
        }
        let _ = a0;
        let scale = 1.0 + qd.norm() * 10.0;
        prop_assert!(cm_pos.norm() < 1e-9, "centre of mass at {}", cm_pos);
        prop_assert!(lin.norm() < 1e-6 * scale, "linear momentum {}", lin);
        prop_assert!(l.abs() < 1e-6 * scale, "angular momentum {}", l);
    }
}

#[test]
fn heavy_base_floating_equals_fixed() {
    // A base of enormous mass and inertia, with joint 1 at its centre, is a fixed base.
    let fl = ArmModel::Floating(FloatingArm {
        links: [1.0, 0.8, 1.2],
        link_masses: [1.0; 3],
        link_inertias: [0.3, 0.2, 0.1],
        base_mass: 1e12,
        base_inertia: 1e12,
        base_offset: 0.0,
    });
    let q = VecN::<3>::new(0.3, -1.2, 2.0);
    let qd = VecN::<3>::new(1.0, 0.5, -2.0);
    let a = kin(&fixed(), 0.0, &q, &qd);
    let b = kin(&fl, 0.0, &q, &qd);
    assert!((a.p - b.p).norm() < 1e-9);
    assert!((a.j - b.j).norm() < 1e-9);
    assert!((a.jdot_qd - b.jdot_qd).norm() < 1e-9);
    assert!(b.base_rate.abs() < 1e-9);
}
