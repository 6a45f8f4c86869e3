//! `chaosctl robot fit-radii`: capsule radii fitted to a robot's collision geometry, for
//! `robot.link_radii`.
//!
//! The filter keeps capsules clear, not the robot: a capsule thinner than its link's housing
//! lets the housing touch an obstacle while the filter reports clearance (MuJoCo saw it on the
//! Panda, docs/mujoco.md). This asks MuJoCo, which has loaded the meshes, for the radius about
//! each of chaosd's segments that encloses every vertex of the link (`plant::mujoco::fit`), and
//! prints it as a config line. The segments are chaosd's own: its forward kinematics give their
//! end points, so the radii are for exactly the capsules the filter sees.

use crate::analysis::mujoco_judge::{LinkFit, MujocoJudge};
use anyhow::{bail, Result};
use control::model::{Chain, JointKind, Pose};
use nalgebra::{Matrix3, Vector3};
use std::path::Path;

/// The end points of chaosd's capsules at `q`: each joint's origin, then the tool point (`tool`
/// in the tip link's frame), in the base frame.
pub fn capsule_points(chain: &Chain, q: &[f64], tool: [f64; 3]) -> Vec<[f64; 3]> {
    let mut pose = Pose::IDENTITY;
    let mut out = Vec::with_capacity(q.len() + 1);
    for (j, &qi) in chain.joints.iter().zip(q) {
        pose = pose.then(&j.placement);
        if j.kind == JointKind::Prismatic {
            pose.pos += pose.rot.column(2) * qi;
        } else {
            let (s, c) = qi.sin_cos();
            pose.rot *= Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        }
        out.push(pose.pos.into());
    }
    let tip = pose.then(&chain.tip_placement);
    out.push(tip.apply(&Vector3::from(tool)).into());
    out
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
    let links = judge.fit(chain, q, &capsule_points(chain, q, tool))?;
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
    let mut out = format!(
        "capsules fitted to {}'s collision geometry in MuJoCo (margin {margin} m):\n\
         link  from → to                      radius (m)  geoms  points  bodies\n",
        chain.robot
    );
    for (j, l) in links.iter().enumerate() {
        let to = if j + 1 < n {
            chain.joints[j + 1].name.as_str()
        } else {
            "tool point"
        };
        let span = format!("{} → {to}", chain.joints[j].name);
        let empty = if l.geoms == 0 { "  (no geometry)" } else { "" };
        out.push_str(&format!(
            "{:>4}  {span:<30} {:>10.4}  {:>5}  {:>6}  {}{empty}\n",
            j + 1,
            l.radius,
            l.geoms,
            l.points,
            l.bodies.join(", ")
        ));
    }
    out
}
