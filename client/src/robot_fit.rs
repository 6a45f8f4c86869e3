//! `chaosctl robot fit-radii`: capsule radii fitted to a robot's collision geometry, for
//! `robot.link_radii`.
//!
//! The filter keeps capsules clear, not the robot: a capsule thinner than its link's housing
//! lets the housing touch an obstacle while the filter reports clearance (MuJoCo saw it on the
//! Panda, docs/mujoco.md). This asks MuJoCo, which has loaded the meshes, for the radius about
//! each of chaosd's segments that encloses every vertex of the link (`plant::mujoco::fit`), and
//! prints it as a config line. The segments are chaosd's own: the end points come from the arm the
//! filter uses (`SpatialArm::capsule_segments`), so the radii are for exactly its capsules.
//! With `--capsules` the judge also fits each link a capsule with end points of its own, along
//! its geometry (`plant::mujoco::fit::own_capsule`), printed in the link's frame for
//! `robot.capsules`.

use crate::analysis::mujoco_judge::{LinkFit, MujocoJudge};
use anyhow::{bail, Result};
use control::arm::spatial::{SpatialArm, SpatialKinematics};
use control::basics::{MAX_JOINTS, MIN_JOINTS};
use control::config::robot::CapsuleEntry;
use control::model::Chain;
use nalgebra::{SVector, Vector3};
use std::path::Path;

/// The end points of chaosd's capsules at `q`: each joint's origin, then the tool point (`tool`
/// in the tip link's frame), in the base frame, from the arm the filter itself uses.
pub fn capsule_points(chain: &Chain, q: &[f64], tool: [f64; 3]) -> Result<Vec<[f64; 3]>> {
    let n = chain.dof();
    if !(MIN_JOINTS..=MAX_JOINTS).contains(&n) || q.len() != n {
        bail!("{} joint angles for a chain of {n} joints ({MIN_JOINTS} to {MAX_JOINTS} are supported)", q.len());
    }
    control::with_dof!(n, N => {
        let mut arm = SpatialArm::new(chain.model::<N>()?);
        arm.tool = Vector3::from(tool);
        let mut k = SpatialKinematics::<N>::default();
        arm.kinematics(&SVector::from_column_slice(q), &SVector::zeros(), &mut k);
        let segments = arm.capsule_segments(&k);
        Ok((0..N)
            .map(|j| segments[j][0])
            .chain(std::iter::once(segments[N - 1][1]))
            .map(|p| [p.x, p.y, p.z])
            .collect())
    })
}

/// What `run` prints: a table and a config line, or one JSON object; radii about the joint
/// origins, or capsules with end points of their own.
#[derive(Clone, Copy, Debug)]
pub struct Output {
    pub json: bool,
    pub capsules: bool,
}

/// Fits and prints: a line per link, then `link_radii = […]` (or with `capsules`, `capsules =
/// […]` in each link's frame), each radius rounded up to the millimetre after `margin` (m) is
/// added.
pub fn run(
    chain: &Chain,
    model: &Path,
    q: &[f64],
    tool: [f64; 3],
    margin: f64,
    out: Output,
) -> Result<()> {
    if !(margin.is_finite() && (0.0..=1.0).contains(&margin)) {
        bail!("--margin {margin}: a length in [0, 1] m");
    }
    let judge = MujocoJudge::new(model, "--mujoco-model")?;
    let links = judge.fit(chain, q, &capsule_points(chain, q, tool)?)?;
    if links.iter().all(|l| l.geoms == 0) {
        bail!(
            "{}: no collision geometry on the arm's links, nothing to fit (a URDF's <collision> \
             elements; robots/*.urdf have none, example-robot-data's meshes do)",
            model.display()
        );
    }
    for (j, l) in links.iter().enumerate().filter(|(_, l)| l.geoms == 0) {
        eprintln!(
            "chaosctl: warning: link {} ({}) has no collision geometry: its radius 0 is a bare segment",
            j + 1,
            l.bodies.join(", ")
        );
    }
    let up = |r: f64| ((r + margin) * 1000.0).ceil() / 1000.0;
    let radii: Vec<f64> = links.iter().map(|l| up(l.radius)).collect();
    let own = if out.capsules {
        Some(own_capsules(chain, q, &links, up)?)
    } else {
        None
    };
    if out.json {
        let mut v = serde_json::json!({
            "link_radii": radii,
            "fitted": links.iter().map(|l| l.radius).collect::<Vec<_>>(),
            "bodies": links.iter().map(|l| &l.bodies).collect::<Vec<_>>(),
        });
        if let Some(own) = &own {
            v["capsules"] = serde_json::json!(own
                .iter()
                .map(|c| serde_json::json!({"a": c.a, "b": c.b, "radius": c.radius}))
                .collect::<Vec<_>>());
        }
        println!("{v}");
        return Ok(());
    }
    print!("{}", table(chain, &links, margin, own.as_deref()));
    match own {
        Some(own) => {
            let rows: Vec<String> = own
                .iter()
                .map(|c| {
                    let f = |p: [f64; 3]| format!("[{:.4}, {:.4}, {:.4}]", p[0], p[1], p[2]);
                    format!(
                        "    {{ a = {}, b = {}, radius = {:.3} }},",
                        f(c.a),
                        f(c.b),
                        c.radius
                    )
                })
                .collect();
            println!("\n[robot]\ncapsules = [\n{}\n]", rows.join("\n"));
        }
        None => {
            let list: Vec<String> = radii.iter().map(|r| format!("{r:.3}")).collect();
            println!("\n[robot]\nlink_radii = [{}]", list.join(", "));
        }
    }
    Ok(())
}

/// The judge's own capsules in each link's URDF frame (what `robot.capsules` reads), radii
/// rounded up by `up` (a link without geometry: its joint segment, bare).
fn own_capsules(
    chain: &Chain,
    q: &[f64],
    links: &[LinkFit],
    up: impl Fn(f64) -> f64,
) -> Result<Vec<CapsuleEntry>> {
    let n = chain.dof();
    control::with_dof!(n, N => {
        let model = chain.model::<N>()?;
        let arm = SpatialArm::new(model);
        let mut k = SpatialKinematics::<N>::default();
        arm.kinematics(&SVector::from_column_slice(q), &SVector::zeros(), &mut k);
        links
            .iter()
            .enumerate()
            .map(|(j, l)| {
                let f = k.frames.link(&arm.model, j);
                let to = |p: [f64; 3]| -> [f64; 3] {
                    let x = f.rot.transpose() * (Vector3::from(p) - f.pos);
                    // Printed to 0.1 mm: rounding each end moves it by at most 0.07 mm, which
                    // the radius takes up.
                    [x.x, x.y, x.z].map(|v| (v * 1e4).round() / 1e4)
                };
                let Some(c) = &l.own else {
                    bail!(
                        "the judge fitted no capsule of its own to link {} (an older \
                         chaosd-mujoco-judge: run scripts/mujoco-setup)",
                        j + 1
                    );
                };
                // The fit's axis has no sign: the ends in one order whatever the pose.
                let (a, b) = (to(c.a), to(c.b));
                let (a, b) = if a.partial_cmp(&b) == Some(std::cmp::Ordering::Greater) {
                    (b, a)
                } else {
                    (a, b)
                };
                Ok(CapsuleEntry {
                    a,
                    b,
                    radius: up(c.radius + 1e-4),
                })
            })
            .collect()
    })
}

fn table(chain: &Chain, links: &[LinkFit], margin: f64, own: Option<&[CapsuleEntry]>) -> String {
    let n = chain.joints.len();
    let spans: Vec<String> = (0..links.len())
        .map(|j| {
            let to = if j + 1 < n {
                chain.joints[j + 1].name.as_str()
            } else {
                "tool point"
            };
            format!("{} → {to}", chain.joints[j].name)
        })
        .collect();
    let w = spans
        .iter()
        .map(|s| s.chars().count())
        .max()
        .unwrap_or(0)
        .max(9);
    let own_head = if own.is_some() {
        "  own capsule (m)"
    } else {
        ""
    };
    let mut out = format!(
        "capsules fitted to {}'s collision geometry in MuJoCo (margin {margin} m):\n\
         link  {:<w$}  radius (m){own_head}  geoms  points  bodies\n",
        chain.robot, "from → to"
    );
    for (j, (l, span)) in links.iter().zip(&spans).enumerate() {
        let pad = w - span.chars().count();
        let own_cell = match (own, &l.own) {
            (Some(_), Some(c)) => format!("  {:>15.4}", c.radius),
            (Some(_), None) => format!("  {:>15}", "–"),
            (None, _) => String::new(),
        };
        out.push_str(&format!(
            "{:>4}  {span}{:pad$}  {:>10.4}{own_cell}  {:>5}  {:>6}  {}\n",
            j + 1,
            "",
            l.radius,
            l.geoms,
            l.points,
            l.bodies.join(", ")
        ));
    }
    out
}
