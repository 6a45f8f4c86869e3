//! `robot.capsules`: capsules with end points of their own in their links' frames, read from a
//! set-up, placed on their links, and kept clear by the filter like the capsules about the joint
//! origins.

use control::arm::spatial::{Segments, SpatialKinematics};
use control::config::robot::CapsuleEntry;
use control::config::SphereEntry;
use control::model::{builtin, Chain};
use control::Config;
use nalgebra::{SVector, Vector3};

type V7 = SVector<f64, 7>;
type Vec3 = Vector3<f64>;

fn panda() -> (Chain, Config) {
    let chain = Chain::from_urdf(builtin("panda").unwrap(), None, None).unwrap();
    (chain, Config::robot_preset("panda").unwrap())
}

fn segments(cfg: &Config, chain: &Chain, q: &V7) -> Segments {
    let s = cfg.setup::<7>(chain).unwrap();
    let mut k = SpatialKinematics::default();
    s.arm.kinematics(q, &V7::zeros(), &mut k);
    s.arm.capsule_segments(&k)
}

/// The preset's capsules (joint origin to joint origin), written as capsules of their own in
/// each link's URDF frame.
fn written_as_own(cfg: &Config, chain: &Chain) -> Vec<CapsuleEntry> {
    let s = cfg.setup::<7>(chain).unwrap();
    let mut k = SpatialKinematics::default();
    s.arm.kinematics(&s.q0, &V7::zeros(), &mut k);
    let segs = s.arm.capsule_segments(&k);
    (0..7)
        .map(|j| {
            let f = k.frames.link(&s.arm.model, j);
            let to = |x: Vec3| (f.rot.transpose() * (x - f.pos)).into();
            CapsuleEntry {
                a: to(segs[j][0]),
                b: to(segs[j][1]),
                radius: s.arm.radii[j],
            }
        })
        .collect()
}

fn with_capsules(cfg: &Config, capsules: Vec<CapsuleEntry>) -> Config {
    let mut own = cfg.clone();
    let r = own.spatial_mut().unwrap();
    r.robot.link_radii = None;
    r.robot.capsules = Some(capsules);
    own
}

/// The distance between sphere `c`, `r` and the capsule `seg`, `radius` (negative: inside).
fn gap(seg: &[Vec3; 2], radius: f64, c: &Vec3, r: f64) -> f64 {
    let [a, b] = seg;
    let e = b - a;
    let t = if e.norm_squared() > 0.0 {
        ((c - a).dot(&e) / e.norm_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + e * t - c).norm() - radius - r
}

/// Capsules of their own placed where the joint-origin capsules are ride on their links as
/// those do: the same segments at every posture, the same run.
#[test]
fn own_capsules_at_the_joint_origins_are_the_presets() {
    let (chain, cfg) = panda();
    let own = with_capsules(&cfg, written_as_own(&cfg, &chain));
    let mut x = 0x1234_u64;
    for _ in 0..20 {
        let q = V7::from_fn(|_, _| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            2.5 * ((x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
        });
        let (a, b) = (segments(&cfg, &chain, &q), segments(&own, &chain, &q));
        for j in 0..7 {
            for e in 0..2 {
                assert!(
                    (a[j][e] - b[j][e]).norm() < 1e-12,
                    "link {j}: {a:?} vs {b:?}"
                );
            }
        }
    }
    // A sphere the filter has to keep clear: both runs the same to rounding.
    let sphere = SphereEntry {
        center: [0.45, -0.05, 0.35],
        radius: 0.08,
        margin: 0.1,
    };
    let run = |c: &Config| {
        let mut c = c.clone();
        c.spatial_mut().unwrap().obstacles.push(sphere.clone());
        let mut sim = c.setup::<7>(&chain).unwrap().simulation();
        let mut acted = 0;
        for _ in 0..5000 {
            acted += (sim.step().flags & control::basics::flags::SAFETY_ACTIVE != 0) as usize;
        }
        (sim.state().q, acted)
    };
    let ((qa, acted), (qb, _)) = (run(&cfg), run(&own));
    assert!(
        acted > 0,
        "the filter never acted: the sphere tests nothing"
    );
    assert!((qa - qb).norm() < 1e-8, "{qa} vs {qb}");
}

/// A capsule moved off its joint line (where a housing hangs) is what the filter keeps clear:
/// a sphere beside it is never entered, while the same run with the capsule on the joint line
/// takes the moved capsule's place into the sphere.
#[test]
fn a_capsule_off_the_joint_line_is_kept_clear() {
    let (chain, cfg) = panda();
    let mut capsules = written_as_own(&cfg, &chain);
    // Link 4 (the elbow to the wrist): 0.1 m off its joint line, in its link frame.
    let link = 3;
    capsules[link].a[0] += 0.1;
    capsules[link].b[0] += 0.1;
    let own = with_capsules(&cfg, capsules.clone());
    let s = own.setup::<7>(&chain).unwrap();
    let mut k = SpatialKinematics::default();
    s.arm.kinematics(&s.q0, &V7::zeros(), &mut k);
    // A sphere on the moved capsule's way: 2 cm deep into where it is 1.5 s into the run
    // without obstacles, clear of every capsule at the start, on the side where the other
    // capsules are farthest.
    let radius = 0.06;
    let required = own.safety.clearance;
    let mut free = s.simulation();
    for _ in 0..1500 {
        free.step();
    }
    let mut later = SpatialKinematics::default();
    s.arm.kinematics(&free.state().q, &V7::zeros(), &mut later);
    let (start, then) = (s.arm.capsule_segments(&k), s.arm.capsule_segments(&later));
    let mid = (then[link][0] + then[link][1]) * 0.5;
    let axis = (then[link][1] - then[link][0]).normalize();
    let side = axis.cross(&Vec3::z()).normalize();
    let depth = capsules[link].radius + radius - 0.02;
    let others = |c: &Vec3| {
        (0..7)
            .filter(|&j| j != link)
            .flat_map(|j| {
                [
                    gap(&start[j], s.arm.radii[j], c, radius),
                    gap(&then[j], s.arm.radii[j], c, radius),
                ]
            })
            .fold(f64::INFINITY, f64::min)
    };
    let center = (0..16)
        .map(|i| {
            let turn = nalgebra::Rotation3::new(axis * (i as f64 * std::f64::consts::TAU / 16.0));
            mid + (turn * side) * depth
        })
        .filter(|c| gap(&start[link], capsules[link].radius, c, radius) > required + 0.02)
        .max_by(|a, b| others(a).total_cmp(&others(b)))
        .expect("a place clear at the start");
    assert!(
        others(&center) > required,
        "the sphere is on another link: {}",
        others(&center)
    );
    let sphere = SphereEntry {
        center: center.into(),
        radius,
        margin: 0.1,
    };
    // The moved capsule's smallest gap to the sphere over a run of `c`.
    let closest = |c: &Config| {
        let mut c = c.clone();
        c.spatial_mut().unwrap().obstacles.push(sphere.clone());
        let mut sim = c.setup::<7>(&chain).unwrap().simulation();
        let mut worst = f64::INFINITY;
        for _ in 0..10_000 {
            sim.step();
            let mut k = SpatialKinematics::default();
            s.arm.kinematics(&sim.state().q, &V7::zeros(), &mut k);
            let seg = s.arm.capsule_segments(&k)[link];
            worst = worst.min(gap(&seg, capsules[link].radius, &center, radius));
        }
        worst
    };
    let kept = closest(&own);
    assert!(
        kept >= required - 1e-3,
        "the moved capsule came {kept} m from the sphere"
    );
    let unguarded = closest(&cfg);
    assert!(
        unguarded < required - 0.01,
        "with the joint-line capsules the moved capsule stayed {unguarded} m clear: the test tests nothing"
    );
}

#[test]
fn bad_capsules_are_refused_with_the_reason() {
    let (chain, cfg) = panda();
    let good = written_as_own(&cfg, &chain);
    let refused = |c: &Config| match c.setup::<7>(&chain) {
        Ok(_) => panic!("accepted"),
        Err(e) => e.to_string(),
    };
    let mut both = with_capsules(&cfg, good.clone());
    both.spatial_mut().unwrap().robot.link_radii = Some(vec![0.05; 7]);
    assert!(refused(&both).contains("not both"), "{}", refused(&both));
    let short = with_capsules(&cfg, good[..6].to_vec());
    assert!(
        refused(&short).contains("7 for this chain"),
        "{}",
        refused(&short)
    );
    let mut nan = good.clone();
    nan[2].a[1] = f64::NAN;
    let e = refused(&with_capsules(&cfg, nan));
    assert!(
        e.contains("robot.capsules[2]") && e.contains("finite"),
        "{e}"
    );
    let mut far = good.clone();
    far[6].b = [0.0, 0.0, 11.0];
    let e = refused(&with_capsules(&cfg, far));
    assert!(e.contains("robot.capsules[6]") && e.contains("10 m"), "{e}");
    let mut negative = good;
    negative[0].radius = -0.01;
    let e = refused(&with_capsules(&cfg, negative));
    assert!(e.contains("robot.capsules[0].radius"), "{e}");
}
