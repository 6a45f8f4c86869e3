//! `chaosctl obstacles --mujoco-judge MODEL`: every robot run of the study judged a second time by
//! MuJoCo over the model's own geometry (a robot's meshes), not by chaosd's capsules.
//!
//! The study's simulation and its filter see the links as capsules; whether the real links
//! stayed clear is a question for geometry the controller never saw. Each run's joint
//! trajectory (one sample every [`SAMPLE_S`]) goes to `chaosd-mujoco-judge` (built by
//! `scripts/mujoco-setup` beside chaosctl), which poses it in MuJoCo and counts contacts. The
//! study then names every run where the filter kept the capsules clear and MuJoCo saw a link
//! touch: the disagreement issue 46 asked to find.

use anyhow::{anyhow, bail, Context, Result};
use control::model::Chain;
use control::Config;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU64, Ordering};

/// The judge's sampling of a trajectory (s): 5 ms, where the arm's links move a few mm.
pub const SAMPLE_S: f64 = 0.005;

/// The program that judges, and the model it judges by.
#[derive(Clone, Debug)]
pub struct MujocoJudge {
    exe: PathBuf,
    model: PathBuf,
}

/// MuJoCo's verdict on one run (the parts of the plant's `ContactReport` the study shows).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Verdict {
    /// Whether the model had collision geometry on the arm to judge by.
    pub judged: bool,
    /// Samples with a link touching an obstacle, and with the arm touching itself.
    pub contact_samples: u64,
    pub self_samples: u64,
    pub first_contact_s: Option<f64>,
    pub first_pair: Option<String>,
    /// The smallest signed distance between a link and an obstacle (m; < 0: penetration).
    pub smallest_distance: Option<f64>,
}

impl MujocoJudge {
    /// Finds `chaosd-mujoco-judge` beside this program and checks the model file (given by the
    /// option `flag`, which errors name).
    pub fn new(model: &Path, flag: &str) -> Result<Self> {
        if !model.is_file() {
            bail!("{flag} {}: no such file", model.display());
        }
        let exe = std::env::current_exe()
            .ok()
            .and_then(|p| p.parent().map(|d| d.join("chaosd-mujoco-judge")))
            .filter(|p| p.is_file())
            .ok_or_else(|| {
                anyhow!(
                    "{flag} needs chaosd-mujoco-judge beside chaosctl: scripts/mujoco-setup \
                     builds it (docs/mujoco.md)"
                )
            })?;
        Ok(Self {
            exe,
            model: model.to_path_buf(),
        })
    }

    /// Judges `samples` (each `t, q1 … qN`, flat) of a run of `cfg` on `chain`.
    pub fn judge(&self, cfg: &Config, chain: &Chain, samples: &[f64]) -> Result<Verdict> {
        let n = chain.dof();
        let spheres: Vec<String> = cfg
            .spatial_part()
            .obstacles
            .iter()
            .map(|o| {
                let [x, y, z] = o.center;
                format!("--sphere={x},{y},{z},{}", o.radius)
            })
            .collect();
        let mut text = String::with_capacity(samples.len() * 12);
        for row in samples.chunks_exact(n + 1) {
            let line: Vec<String> = row.iter().map(|v| format!("{v:e}")).collect();
            text.push_str(&line.join(" "));
            text.push('\n');
        }
        let out = self.run(chain, &spheres, &text)?;
        let v: Value = serde_json::from_slice(&out).context("the judge's answer")?;
        Ok(Verdict {
            judged: v["judged"].as_bool().unwrap_or(false),
            contact_samples: v["obstacle_contact_periods"].as_u64().unwrap_or(0),
            self_samples: v["self_contact_periods"].as_u64().unwrap_or(0),
            first_contact_s: v["first_contact_s"].as_f64(),
            first_pair: v["first_pair"].as_str().map(str::to_string),
            smallest_distance: v["smallest_distance_m"].as_f64(),
        })
    }
}

/// One link's fitted capsule, as the judge reports it ([`MujocoJudge::fit`]).
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
pub struct LinkFit {
    pub radius: f64,
    pub bodies: Vec<String>,
    pub geoms: usize,
    pub points: usize,
    /// The tighter capsule with end points of its own (base frame), when the link has geometry.
    #[serde(default)]
    pub own: Option<OwnCapsule>,
}

/// A capsule along a link's own geometry, as the judge fits it (base frame at the fit's pose).
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize)]
pub struct OwnCapsule {
    pub a: [f64; 3],
    pub b: [f64; 3],
    pub radius: f64,
}

impl MujocoJudge {
    /// The capsule radii that enclose the model's geometry about chaosd's segments: `points`
    /// are the segments' end points (each joint's origin, then the tool point; base frame) at
    /// the pose `q` of `chain`'s joints.
    pub fn fit(&self, chain: &Chain, q: &[f64], points: &[[f64; 3]]) -> Result<Vec<LinkFit>> {
        let points: Vec<String> = points
            .iter()
            .map(|[x, y, z]| format!("--point={x:e},{y:e},{z:e}"))
            .collect();
        let pose: Vec<String> = std::iter::once(0.0)
            .chain(q.iter().copied())
            .map(|v| format!("{v:e}"))
            .collect();
        let out = self.run(chain, &points, &(pose.join(" ") + "\n"))?;
        serde_json::from_slice(&out).context("the judge's fit")
    }

    /// Runs the judge on `chain`'s joints with `args`, `input` on its standard input; its
    /// standard output, or its error line.
    fn run(&self, chain: &Chain, args: &[String], input: &str) -> Result<Vec<u8>> {
        let joints: Vec<&str> = chain.joints.iter().map(|j| j.name.as_str()).collect();
        // The input goes in as a file, not a pipe: chaosctl keeps SIGPIPE's default (for
        // `| head`), and a judge that fails early would otherwise end chaosctl with it.
        let file = Scratch::new(input)?;
        let out = Command::new(&self.exe)
            .arg("--model")
            .arg(&self.model)
            .arg("--joints")
            .arg(joints.join(","))
            .args(args)
            .stdin(std::fs::File::open(&file.0)?)
            .output()
            .with_context(|| format!("cannot run {}", self.exe.display()))?;
        if !out.status.success() {
            bail!("{}", String::from_utf8_lossy(&out.stderr).trim());
        }
        Ok(out.stdout)
    }
}

/// A trajectory file of this process's, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(text: &str) -> Result<Self> {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let path = std::env::temp_dir().join(format!(
            "chaosctl-judge-{}-{}.txt",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
        Ok(Self(path))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}
