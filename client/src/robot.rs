//! `chaosctl robot`: look at a robot model and evaluate it at one state.
//!
//! This is how a user checks a description before a controller drives it, and how scripts
//! compare chaosd with pinocchio: `eval --json` prints exactly the quantities the golden tests
//! compare, from the same function (`Chain::evaluate`).

use anyhow::{bail, Context};
use control::model::{Chain, ChainJoint};
use nalgebra::Vector3;

#[derive(clap::Args, Debug)]
pub struct RobotCmd {
    #[command(subcommand)]
    action: Action,
}

#[derive(clap::Subcommand, Debug)]
enum Action {
    /// The chain: joints, axes, limits, link masses, total mass and reach.
    Show {
        #[command(flatten)]
        which: Which,
    },
    /// Pose, Jacobian, J̇q̇, mass matrix, RNEA, gravity and ABA at one state.
    Eval {
        #[command(flatten)]
        which: Which,
        /// Joint positions, a comma list (rad or m); missing vectors are zero.
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Joint velocities.
        #[arg(long, allow_hyphen_values = true)]
        qd: Option<String>,
        /// Joint accelerations (for RNEA).
        #[arg(long, allow_hyphen_values = true)]
        qdd: Option<String>,
        /// Joint torques or forces (for ABA).
        #[arg(long, allow_hyphen_values = true)]
        tau: Option<String>,
        /// One JSON object: tip_pose, jacobian, jdot_qd, mass_matrix, rnea, gravity, aba.
        #[arg(long)]
        json: bool,
    },
    /// Capsule radii that enclose the robot's collision geometry, for `robot.link_radii`:
    /// MuJoCo loads the model's meshes and measures each link about chaosd's segment
    /// (chaosd-mujoco-judge, built by scripts/mujoco-setup; docs/mujoco.md).
    FitRadii {
        #[command(flatten)]
        which: Which,
        /// The model with the collision geometry (URDF or MJCF; its joints named as the chain's),
        /// e.g. out/mujoco/panda.urdf, example-robot-data's Panda with its meshes.
        #[arg(long = "mujoco-model", value_name = "MODEL")]
        model: std::path::PathBuf,
        /// The tool point in the tip link's frame, x,y,z (m): where the last capsule ends, as
        /// robot.tool.
        #[arg(long, allow_hyphen_values = true)]
        tool: Option<String>,
        /// The pose to measure at, a comma list (default: each joint mid-range). The radii are
        /// the same at every pose, but for geometry on joints that are not the chain's.
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Added to each radius before it is rounded up to the millimetre (m).
        #[arg(long, default_value_t = 0.0)]
        margin: f64,
        /// One JSON object: link_radii (rounded), fitted (exact), bodies (and capsules).
        #[arg(long)]
        json: bool,
        /// Fit capsules with end points of their own, along each link's geometry, and print
        /// them as `[robot] capsules` (far tighter than radii about the joint origins where a
        /// housing hangs off the joint line).
        #[arg(long)]
        capsules: bool,
    },
}

#[derive(clap::Args, Debug)]
struct Which {
    /// A built-in robot (panda, planar3) or a path to a URDF file.
    robot: String,
    /// The chain's base link (default: the root link).
    #[arg(long)]
    base: Option<String>,
    /// The chain's tip link (default: the only leaf).
    #[arg(long)]
    tip: Option<String>,
    /// Gravity in the base frame, m/s² (default 0,0,-9.81).
    #[arg(long, allow_hyphen_values = true)]
    gravity: Option<String>,
}

impl Which {
    fn load(&self) -> anyhow::Result<Chain> {
        let mut chain = rt::robot::load(&self.robot, self.base.as_deref(), self.tip.as_deref())?;
        if let Some(g) = &self.gravity {
            let g = parse_list("--gravity", g, 3, "x,y,z")?;
            chain.gravity = Vector3::new(g[0], g[1], g[2]);
        }
        Ok(chain)
    }
}

pub fn run(cmd: RobotCmd) -> anyhow::Result<()> {
    match cmd.action {
        Action::FitRadii {
            which,
            model,
            tool,
            q,
            margin,
            json,
            capsules,
        } => {
            let chain = which.load()?;
            let n = chain.dof();
            let q = match q {
                Some(text) => parse_list("--q", &text, n, "one per joint")?,
                None => chain.joints.iter().map(mid_range).collect(),
            };
            let tool = match tool {
                Some(text) => {
                    let t = parse_list("--tool", &text, 3, "x,y,z")?;
                    let max = control::config::spatial::MAX_TOOL_M;
                    if t.iter().map(|v| v * v).sum::<f64>().sqrt() > max {
                        bail!("--tool {text}: at most {max} m from the tip link's origin");
                    }
                    [t[0], t[1], t[2]]
                }
                None => [0.0; 3],
            };
            let out = crate::robot_fit::Output { json, capsules };
            crate::robot_fit::run(&chain, &model, &q, tool, margin, out)
        }
        Action::Show { which } => {
            let chain = which.load()?;
            print!("{}", describe(&chain, &which.robot));
            Ok(())
        }
        Action::Eval {
            which,
            q,
            qd,
            qdd,
            tau,
            json,
        } => {
            let chain = which.load()?;
            let n = chain.dof();
            let vec = |name, v: &Option<String>| match v {
                Some(text) => parse_list(name, text, n, "one per joint"),
                None => Ok(vec![0.0; n]),
            };
            let e = chain.evaluate(
                &vec("--q", &q)?,
                &vec("--qd", &qd)?,
                &vec("--qdd", &qdd)?,
                &vec("--tau", &tau)?,
            )?;
            finite(&chain, &e)?;
            if json {
                println!("{}", serde_json::to_string(&e)?);
            } else {
                print!("{}", pretty(&e, n));
            }
            Ok(())
        }
    }
}

/// The middle of a joint's range, or 0 where it has no finite range.
fn mid_range(j: &ChainJoint) -> f64 {
    let (lo, hi) = (j.limits.lower, j.limits.upper);
    if lo.is_finite() && hi.is_finite() {
        0.5 * (lo + hi)
    } else {
        0.0
    }
}

/// A comma list of exactly `n` finite numbers (`what` says why `n`).
fn parse_list(name: &str, text: &str, n: usize, what: &str) -> anyhow::Result<Vec<f64>> {
    let v = text
        .split(',')
        .map(|s| {
            let s = s.trim();
            s.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .with_context(|| format!("{name}: {s:?} is not a finite number"))
        })
        .collect::<anyhow::Result<Vec<f64>>>()?;
    if v.len() != n {
        bail!("{name} has {} entries; expected {n} ({what})", v.len());
    }
    Ok(v)
}

fn limit(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.4}")
    } else {
        "-".into()
    }
}

fn joint_row(i: usize, j: &ChainJoint, w: usize) -> String {
    let a = j.axis;
    format!(
        "{:>2}  {:<w$} {:<10} ({:>5.2}, {:>5.2}, {:>5.2})  {:>8} {:>8} {:>8} {:>8}  {:>8.3}  {}\n",
        i + 1,
        j.name,
        j.kind.name(),
        a.x,
        a.y,
        a.z,
        limit(j.limits.lower),
        limit(j.limits.upper),
        limit(j.limits.velocity),
        limit(j.limits.effort),
        j.body.mass,
        j.links.join(", ")
    )
}

/// The `robot show` text.
pub fn describe(chain: &Chain, spec: &str) -> String {
    let mut s = format!(
        "robot {:?} ({spec}): chain {} -> {}, {} joints\n",
        chain.robot,
        chain.base,
        chain.tip,
        chain.dof()
    );
    let w = chain
        .joints
        .iter()
        .map(|j| j.name.len())
        .max()
        .unwrap_or(5)
        .max(5);
    s.push_str(&format!(
        "{:>2}  {:<w$} {:<10} {:<21}  {:>8} {:>8} {:>8} {:>8}  {:>8}  {}\n",
        "#",
        "joint",
        "type",
        "axis (own frame)",
        "lower",
        "upper",
        "velocity",
        "effort",
        "mass kg",
        "links (body)"
    ));
    for (i, j) in chain.joints.iter().enumerate() {
        s.push_str(&joint_row(i, j, w));
    }
    let g = chain.gravity;
    s.push_str(&format!(
        "total mass {:.3} kg moved by the joints (the base and what hangs off it are ground)\n\
         reach {:.3} m (joint 1 to the tip, at full stretch)\n\
         gravity ({}, {}, {}) m/s² in the base frame\n",
        chain.mass(),
        chain.reach(),
        g.x,
        g.y,
        g.z
    ));
    if let Some(e) = chain.massless_joint("") {
        s.push_str(&format!("warning: {e}\n"));
    } else if let Some(c) = mass_matrix_condition(chain).filter(|&c| c > BAD_CONDITION) {
        s.push_str(&format!(
            "warning: the mass matrix at q = 0 has condition number {c:.1e}: a body nearly without inertia makes the forward dynamics (torque, position and velocity modes on the rigid-body plant) stiff or inaccurate\n"
        ));
    }
    s
}

/// A mass matrix worse conditioned than this is named by `robot show` (the Panda's is about
/// 1e3; iCub's neck, with a head of 1e-35 kg·m², about 1e17).
const BAD_CONDITION: f64 = 1e10;

/// The mass matrix's condition number at q = 0 (largest over smallest eigenvalue), or None
/// when it cannot be evaluated.
fn mass_matrix_condition(chain: &Chain) -> Option<f64> {
    let n = chain.dof();
    let z = vec![0.0; n];
    let e = chain.evaluate(&z, &z, &z, &z).ok()?;
    let m = nalgebra::DMatrix::from_row_slice(n, n, &e.mass_matrix);
    let eig = m.symmetric_eigenvalues();
    let (lo, hi) = (eig.min(), eig.max());
    (lo.is_finite() && hi.is_finite()).then(|| if lo > 0.0 { hi / lo } else { f64::INFINITY })
}

/// Refuses an evaluation with a non-finite number in it, naming the cause where it is known:
/// no command prints a NaN and exits 0.
fn finite(chain: &Chain, e: &control::model::Evaluation) -> anyhow::Result<()> {
    let parts = e.named();
    let Some((name, _)) = parts.iter().find(|(_, v)| v.iter().any(|x| !x.is_finite())) else {
        return Ok(());
    };
    match chain.massless_joint("") {
        Some(cause) => bail!("{name} is not finite at this state: {cause}"),
        None => bail!("{name} is not finite at this state (the mass matrix is singular there, or the state too large)"),
    }
}

fn pretty(e: &control::model::Evaluation, n: usize) -> String {
    let rows = |name: &str, v: &[f64], cols: usize| {
        let mut s = format!("{name}\n");
        for r in v.chunks(cols) {
            let line: Vec<String> = r.iter().map(|x| format!("{x:>12.6}")).collect();
            s.push_str(&format!("  {}\n", line.join(" ")));
        }
        s
    };
    [
        rows("tip pose (4×4, base frame)", &e.tip_pose, 4),
        rows("jacobian (6×n: vx vy vz wx wy wz)", &e.jacobian, n),
        rows(
            "jdot_qd (classical acceleration of the tip at q̈ = 0: linear, angular)",
            &e.jdot_qd,
            6,
        ),
        rows("mass matrix", &e.mass_matrix, n),
        rows("rnea τ(q, q̇, q̈)", &e.rnea, n),
        rows("gravity g(q)", &e.gravity, n),
        rows("aba q̈(q, q̇, τ)", &e.aba, n),
    ]
    .concat()
}
