//! Capsules fitted to a robot's collision geometry: for each of chaosd's links, the radius that
//! encloses every piece of the model's geometry the link carries.
//!
//! chaosd's filter keeps capsules clear: link j is the segment from joint j's origin to joint
//! j + 1's (the last link's ends at the tool point), with the radius `robot.link_radii` gives.
//! On the Panda the preset's radii leave the housings of joints 5 and 6 outside their capsules,
//! so MuJoCo saw the meshes touch where the capsules stayed clear (docs/mujoco.md). The radius
//! that closes that gap is a property of the model alone: each capsule is rigid with the body
//! its joint moves, so the largest distance from the segment to any vertex of that body's geoms
//! (and of the bodies welded to it without one of chaosd's joints, a hand and its fingers) is
//! the same at every pose. The distance to a segment is convex, so over a mesh (or a box) its
//! largest value is at a vertex: the radius is exact for the geometry MuJoCo collides.
//!
//! ```no_run
//! use plant::mujoco::fit;
//! use std::collections::BTreeMap;
//! let joints: Vec<String> = (1..=7).map(|i| format!("panda_joint{i}")).collect();
//! let q = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785];
//! // chaosd's capsule end points at q (base frame): `chaosctl robot fit-radii` computes them.
//! let points = vec![[0.0; 3]; 8];
//! let model = std::path::Path::new("out/mujoco/panda.urdf");
//! let links = fit::fit(model, &BTreeMap::new(), &joints, &q, &points).unwrap();
//! println!("{:?}", links.iter().map(|l| l.radius).collect::<Vec<_>>());
//! ```

use super::load::{self, Source};
use anyhow::{bail, Result};
use mujoco_rs::mujoco_c::{mjData, mjModel, mj_kinematics, mjtObj};
use mujoco_rs::prelude::*;
use nalgebra::Vector3;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What one of chaosd's links needs to enclose its geometry.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LinkFit {
    /// The smallest capsule radius about the link's segment that holds all its geoms (m).
    pub radius: f64,
    /// The model's bodies the link carries (its joint's body, then those welded to it).
    pub bodies: Vec<String>,
    /// Geoms measured, and the points (mesh vertices, box corners, …) they gave.
    pub geoms: usize,
    pub points: usize,
    /// A capsule with end points of its own that holds the same geometry, usually far tighter
    /// ([`own_capsule`]; world frame at the fit's pose); a link without geometry keeps its
    /// segment, bare.
    pub own: Option<OwnCapsule>,
}

/// A capsule placed along a link's geometry rather than between chaosd's joint origins.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct OwnCapsule {
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub radius: f64,
}

/// Poses `model` at `q` (chaosd's `joints`) and fits each link's capsule about chaosd's segment
/// from `points[j]` to `points[j + 1]` (base frame, at the same q; one more than the joints).
pub fn fit(
    model: &Path,
    packages: &BTreeMap<String, PathBuf>,
    joints: &[String],
    q: &[f64],
    points: &[[f64; 3]],
) -> Result<Vec<LinkFit>> {
    let n = joints.len();
    if q.len() != n || points.len() != n + 1 {
        bail!(
            "{} joint angles and {} capsule points for {n} joints (expected {n} and {})",
            q.len(),
            points.len(),
            n + 1
        );
    }
    let segments: Vec<[[f64; 3]; 2]> = points.windows(2).map(|w| [w[0], w[1]]).collect();
    fit_segments(load::Source::File(model), packages, joints, q, &segments)
}

/// [`fit`] about any segment per link (`segments[j]`, base frame at `q`): a set-up's capsules
/// with end points of their own, too.
pub fn fit_segments(
    source: Source<'_>,
    packages: &BTreeMap<String, PathBuf>,
    joints: &[String],
    q: &[f64],
    segments: &[[[f64; 3]; 2]],
) -> Result<Vec<LinkFit>> {
    let n = joints.len();
    if q.len() != n || segments.len() != n {
        bail!(
            "{} joint angles and {} capsule segments for {n} joints",
            q.len(),
            segments.len()
        );
    }
    let built = load::build(source, packages, (&[], q), joints, 1e-3)?;
    let mut data = MjData::new(built.model);
    let m: *const mjModel = data.model().ffi();
    // SAFETY: the data owns the model; the addresses come from the model's joint table.
    let (m, d) = unsafe { (&*m, data.ffi_mut()) };
    for (&(a, _), &v) in built.arm.iter().zip(q) {
        // SAFETY: `a` is a qpos address of the model.
        unsafe { *d.qpos.add(a) = v };
    }
    // SAFETY: a live model and its data.
    unsafe { mj_kinematics(m, d) };
    let owner = link_of_bodies(m, joints)?;
    let mut links: Vec<LinkFit> = (0..n)
        .map(|_| LinkFit {
            radius: 0.0,
            bodies: Vec::new(),
            geoms: 0,
            points: 0,
            own: None,
        })
        .collect();
    let mut held: Vec<Vec<(Vector3<f64>, f64)>> = vec![Vec::new(); n];
    for (b, link) in owner.iter().enumerate() {
        if let Some(j) = *link {
            links[j]
                .bodies
                .push(load::name_of(m, mjtObj::mjOBJ_BODY, b));
        }
    }
    let ngeom = m.ngeom as usize;
    for g in (0..ngeom).filter(|g| !built.obstacles.contains(g)) {
        // SAFETY: g < ngeom.
        let body = unsafe { *m.geom_bodyid.add(g) } as usize;
        let Some(j) = owner[body] else { continue };
        let [a, b] = segments[j];
        let mut far = 0.0f64;
        let count = geom_points(m, d, g, |p, pad| {
            far = far.max(segment_distance(&a, &b, &p) + pad);
            held[j].push((Vector3::from(p), pad));
        });
        links[j].radius = links[j].radius.max(far);
        links[j].geoms += 1;
        links[j].points += count;
    }
    for (j, (link, points)) in links.iter_mut().zip(&held).enumerate() {
        // The axis of a stubby link's geometry can fit worse than chaosd's own segment: the
        // smaller of the two.
        let along = OwnCapsule {
            a: segments[j][0],
            b: segments[j][1],
            radius: link.radius,
        };
        // A link without geometry keeps chaosd's segment, bare (radius 0), as with the radii.
        link.own = Some(match own_capsule(points) {
            Some(own) if volume(&own) <= volume(&along) => own,
            _ => along,
        });
    }
    Ok(links)
}

/// A capsule's volume, π R² (L + 4R/3).
fn volume(c: &OwnCapsule) -> f64 {
    let l = (Vector3::from(c.b) - Vector3::from(c.a)).norm();
    std::f64::consts::PI * c.radius * c.radius * (l + 4.0 / 3.0 * c.radius)
}

/// Lengths tried for the capsule's radius, as multiples of the thinnest that holds the points
/// about their axis: a longer segment with a thinner radius, or the reverse.
const RADIUS_STEPS: usize = 41;

/// The capsule of least volume, among those about the points' principal axis, that holds every
/// point `p` with its pad `r` (a ball of radius r about p); None without points. For a radius R
/// the segment's ends are as close together as the points allow: a point at t along the axis and
/// d from it lies inside once an end is within √((R − r)² − d²) of t. The radius returned is the
/// exact largest distance from the segment (plus pad), so the capsule holds every point.
pub fn own_capsule(points: &[(Vector3<f64>, f64)]) -> Option<OwnCapsule> {
    if points.is_empty() {
        return None;
    }
    let c = points.iter().map(|(p, _)| p).sum::<Vector3<f64>>() / points.len() as f64;
    let spread: nalgebra::Matrix3<f64> = points
        .iter()
        .map(|(p, _)| (p - c) * (p - c).transpose())
        .sum();
    let eig = spread.symmetric_eigen();
    let axis = eig.eigenvectors.column(eig.eigenvalues.imax()).into_owned();
    let polar: Vec<(f64, f64, f64)> = points
        .iter()
        .map(|(p, pad)| {
            let t = (p - c).dot(&axis);
            (t, (p - c - axis * t).norm(), *pad)
        })
        .collect();
    let thinnest = polar.iter().map(|&(_, d, r)| d + r).fold(0.0, f64::max);
    let mut best: Option<(f64, OwnCapsule)> = None;
    for k in 0..RADIUS_STEPS {
        let radius = thinnest * (1.0 + 0.05 * k as f64) + 1e-12;
        let reach = |d: f64, r: f64| ((radius - r).powi(2) - d * d).max(0.0).sqrt();
        let lo = polar
            .iter()
            .map(|&(t, d, r)| t + reach(d, r))
            .fold(f64::INFINITY, f64::min);
        let hi = polar
            .iter()
            .map(|&(t, d, r)| t - reach(d, r))
            .fold(f64::NEG_INFINITY, f64::max);
        let (lo, hi) = if lo <= hi {
            (lo, hi)
        } else {
            ((lo + hi) / 2.0, (lo + hi) / 2.0)
        };
        let (a, b) = (c + axis * lo, c + axis * hi);
        let (a, b) = ([a.x, a.y, a.z], [b.x, b.y, b.z]);
        let held = points
            .iter()
            .map(|(p, pad)| segment_distance(&a, &b, &[p.x, p.y, p.z]) + pad)
            .fold(0.0, f64::max);
        let capsule = OwnCapsule { a, b, radius: held };
        let v = volume(&capsule);
        if best.as_ref().is_none_or(|(least, _)| v < *least) {
            best = Some((v, capsule));
        }
    }
    best.map(|(_, capsule)| capsule)
}

/// Which of chaosd's links carries each body: the link of its joint, or of the nearest body
/// above it with one of chaosd's joints (`None`: the fixed base and what is welded to it).
fn link_of_bodies(m: &mjModel, joints: &[String]) -> Result<Vec<Option<usize>>> {
    let (nbody, njnt) = (m.nbody as usize, m.njnt as usize);
    // SAFETY: MuJoCo's per-body and per-joint arrays have nbody and njnt entries.
    let (parent, jbody) = unsafe {
        (
            std::slice::from_raw_parts(m.body_parentid, nbody),
            std::slice::from_raw_parts(m.jnt_bodyid, njnt),
        )
    };
    let mut own = vec![None; nbody];
    for (i, name) in joints.iter().enumerate() {
        let Some(j) = (0..njnt).find(|&j| load::name_of(m, mjtObj::mjOBJ_JOINT, j) == *name) else {
            bail!("the MuJoCo model has no joint {name:?}");
        };
        own[jbody[j] as usize] = Some(i);
    }
    // Parents come before their children in MuJoCo's body order.
    let mut out = vec![None; nbody];
    for b in 1..nbody {
        out[b] = own[b].or(out[parent[b] as usize]);
    }
    Ok(out)
}

/// Calls `visit(point, pad)` for the points that bound geom `g` in the world (a mesh's
/// vertices, a box's corners, a sphere's centre with its radius as `pad`); returns how many.
fn geom_points(m: &mjModel, d: &mjData, g: usize, mut visit: impl FnMut([f64; 3], f64)) -> usize {
    // SAFETY: g < ngeom; geom_xpos and geom_xmat hold 3 and 9 numbers a geom after kinematics;
    // geom_size 3; a mesh's vertices are `mesh_vertnum` floats triples from `mesh_vertadr`.
    unsafe {
        let pos = std::slice::from_raw_parts(d.geom_xpos.add(3 * g), 3);
        let rot = std::slice::from_raw_parts(d.geom_xmat.add(9 * g), 9);
        let size = std::slice::from_raw_parts(m.geom_size.add(3 * g), 3);
        let world = |v: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|r| {
                pos[r] + rot[3 * r] * v[0] + rot[3 * r + 1] * v[1] + rot[3 * r + 2] * v[2]
            })
        };
        let corners = |h: [f64; 3], visit: &mut dyn FnMut([f64; 3], f64)| {
            for k in 0..8 {
                let s = |bit: usize| if k >> bit & 1 == 1 { 1.0 } else { -1.0 };
                visit(world([s(0) * h[0], s(1) * h[1], s(2) * h[2]]), 0.0);
            }
            8
        };
        match *m.geom_type.add(g) {
            // mjGEOM_MESH: every vertex, in the geom's frame.
            7 => {
                let mesh = *m.geom_dataid.add(g) as usize;
                let at = *m.mesh_vertadr.add(mesh) as usize;
                let count = *m.mesh_vertnum.add(mesh) as usize;
                let v = std::slice::from_raw_parts(m.mesh_vert.add(3 * at), 3 * count);
                for p in v.chunks_exact(3) {
                    visit(world([p[0].into(), p[1].into(), p[2].into()]), 0.0);
                }
                count
            }
            // mjGEOM_BOX, mjGEOM_CYLINDER (its bounding box): the corners.
            6 => corners([size[0], size[1], size[2]], &mut visit),
            5 => corners([size[0], size[0], size[1]], &mut visit),
            // mjGEOM_CAPSULE: the two ends, padded by the radius.
            3 => {
                visit(world([0.0, 0.0, size[1]]), size[0]);
                visit(world([0.0, 0.0, -size[1]]), size[0]);
                2
            }
            // mjGEOM_SPHERE, mjGEOM_ELLIPSOID (its largest semi-axis): the centre, padded.
            2 => {
                visit(world([0.0; 3]), size[0]);
                1
            }
            4 => {
                visit(world([0.0; 3]), size[0].max(size[1]).max(size[2]));
                1
            }
            // A plane, height field or SDF on an arm link: its bounding sphere.
            _ => {
                visit(world([0.0; 3]), *m.geom_rbound.add(g));
                1
            }
        }
    }
}

/// The distance from `p` to the segment [a, b], by the filter's own closest point
/// ([`control::secondary::spatial::segment_parameter`]).
fn segment_distance(a: &[f64; 3], b: &[f64; 3], p: &[f64; 3]) -> f64 {
    let (a, b, p) = (Vector3::from(*a), Vector3::from(*b), Vector3::from(*p));
    let t = control::secondary::spatial::segment_parameter(&a, &b, &p);
    (p - (a + (b - a) * t)).norm()
}

#[cfg(test)]
mod tests {
    use super::{own_capsule, segment_distance};
    use nalgebra::Vector3;

    /// The points of a cylinder of radius 0.05 from z = 0.1 to 0.4 off the origin's axis: the
    /// capsule holds every point, lies along the cylinder and is far thinner than one about the
    /// z axis through the origin would be.
    #[test]
    fn an_own_capsule_holds_its_points_tightly() {
        let mut points = Vec::new();
        for i in 0..40 {
            let a = i as f64 * std::f64::consts::TAU / 40.0;
            for z in [0.1, 0.2, 0.3, 0.4] {
                points.push((Vector3::new(0.2 + 0.05 * a.cos(), 0.05 * a.sin(), z), 0.0));
            }
        }
        points.push((Vector3::new(0.2, 0.0, 0.25), 0.01));
        let c = own_capsule(&points).unwrap();
        for (p, pad) in &points {
            assert!(segment_distance(&c.a, &c.b, &[p.x, p.y, p.z]) + pad <= c.radius + 1e-12);
        }
        assert!(c.radius < 0.08, "{c:?}");
        assert!(
            (c.a[0] - 0.2).abs() < 1e-9 && (c.b[0] - 0.2).abs() < 1e-9,
            "{c:?}"
        );
        assert!(own_capsule(&[]).is_none());
    }

    #[test]
    fn the_distance_to_a_segment_is_to_its_nearest_point() {
        let (a, b) = ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
        assert_eq!(segment_distance(&a, &b, &[0.3, 0.0, 0.5]), 0.3);
        assert_eq!(segment_distance(&a, &b, &[0.0, 0.0, 1.5]), 0.5);
        assert_eq!(segment_distance(&a, &b, &[0.0, 0.4, -0.3]), 0.5);
        // A segment of no length is a point.
        assert_eq!(segment_distance(&a, &a, &[0.0, 3.0, 4.0]), 5.0);
    }
}
