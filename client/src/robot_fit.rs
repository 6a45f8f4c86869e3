//! `chaosctl robot fit-radii`: capsule radii fitted to a robot's collision geometry, for
//! `robot.link_radii`.
//!
//! The filter keeps capsules clear, not the robot: a capsule thinner than its link's housing
//! lets the housing touch an obstacle while the filter reports clearance (MuJoCo saw it on the
//! Panda, docs/mujoco.md). This asks MuJoCo, which has loaded the meshes, for the radius about
//! each of chaosd's segments that encloses every vertex of the link (`plant::mujoco::fit`), and
//! prints it as a config line. The segments are chaosd's own: the end points come from the arm the
//! filter uses (`SpatialArm::capsule_positions`), so the radii are for exactly its capsules.

use crate::analysis::mujoco_judge::{LinkFit, MujocoJudge};
use anyhow::{bail, Result};
use control::arm::spatial::{SpatialArm, SpatialKinematics};
use control::basics::{MAX_JOINTS, MIN_JOINTS};
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
        Ok(arm.capsule_positions(&k)[..=N].iter().map(|p| [p.x, p.y, p.z]).collect())
    })
}

/// Fits and prints: a line per link, then `link_radii = […]`, each rounded up to the
/// millimetre after `margin` (m) is added.
pub fn run(
    chain: &Chain,
    model: &Path,
    q: &[f64],
    tool: [f64; 3],
    margin: f64,
    json: bool,
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
    let radii: Vec<f64> = links
        .iter()
        .map(|l| ((l.radius + margin) * 1000.0).ceil() / 1000.0)
        .collect();
    if json {
        let v = serde_json::json!({
            "link_radii": radii,
            "fitted": links.iter().map(|l| l.radius).collect::<Vec<_>>(),
            "bodies": links.iter().map(|l| &l.bodies).collect::<Vec<_>>(),
        });
        println!("{v}");
        return Ok(());
    }
    print!("{}", table(chain, &links, margin));
    let list: Vec<String> = radii.iter().map(|r| format!("{r:.3}")).collect();
    println!("\n[robot]\nlink_radii = [{}]", list.join(", "));
    Ok(())
}

fn table(chain: &Chain, links: &[LinkFit], margin: f64) -> String {
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
    let mut out = format!(
        "capsules fitted to {}'s collision geometry in MuJoCo (margin {margin} m):\n\
         link  {:<w$}  radius (m)  geoms  points  bodies\n",
        chain.robot, "from → to"
    );
    for (j, (l, span)) in links.iter().zip(&spans).enumerate() {
        let pad = w - span.chars().count();
        out.push_str(&format!(
            "{:>4}  {span}{:pad$}  {:>10.4}  {:>5}  {:>6}  {}\n",
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
