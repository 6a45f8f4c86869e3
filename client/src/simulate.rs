//! `chaosctl simulate`: one deterministic closed-loop run, summarised for a person or as JSON.

use crate::setup::ModelArgs;
use crate::subject::{LoopVisitor, Start, Subject};
use crate::traps::{OfflineTraps, TrapEvent};
use anyhow::{bail, Context, Result};
use clap::Args;
use control::config::{ModelKind, ProjectionKind};
use control::sim::{run_steering_at, ClosedLoopLaw};
use control::{ArmState, Simulation, Summary};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SimulateArgs {
    #[command(flatten)]
    pub model: ModelArgs,
    /// Simulated time (s).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Statistics skip this initial transient (s).
    #[arg(long)]
    pub transient: Option<f64>,
    /// Write the trajectory as CSV: t,[phi,]q1..qn,qd1..qdn.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Write every N-th step to the CSV.
    #[arg(long, default_value_t = 10)]
    pub stride: u64,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `simulate` prints, for every arm.
#[derive(Serialize)]
pub struct Report {
    /// `"planar"`, or the robot's description (a built-in name or a URDF path).
    pub robot: String,
    /// The planar arm's base: fixed or floating (a robot's is fixed; not printed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<ModelKind>,
    pub n: usize,
    /// Which rows the law tracks and along which path (`position circle`, `pose eight`).
    pub task: String,
    pub secondary: String,
    pub alpha: f64,
    pub mu: f64,
    pub tau: f64,
    pub t_on: f64,
    pub dt: f64,
    /// Where the Pyragas term acts: "full" or "null-space".
    pub projection: ProjectionKind,
    pub steps: u64,
    pub final_time: f64,
    pub final_q: Vec<f64>,
    pub final_qd: Vec<f64>,
    pub final_phi: Option<f64>,
    /// Steered onto a planned clean cycle from the start (`safety.plan`), which replaces the
    /// secondary task.
    pub steered: bool,
    /// With `safety.plan`: the steering onto a planned clean cycle, or why there is none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan: Option<String>,
    /// The trap watch's answers, as the daemon would give them (safety on).
    pub traps: Vec<TrapEvent>,
    #[serde(flatten)]
    pub summary: Summary,
}

/// One state of a run as [`run_subject`] hands it out.
pub struct Visited<'a> {
    /// The grid step (t = k·dt) and its time (s).
    pub k: u64,
    pub t: f64,
    pub q: &'a [f64],
    pub qd: &'a [f64],
    /// The planar floating base's attitude (0 for every other arm).
    pub phi: f64,
    /// What the law made of this state; None for the final one, from which no step is taken.
    pub law: Option<LawView>,
}

/// What the law saw at one state: the tool, how far it is from its target, the clearance.
#[derive(Clone, Copy, Debug)]
pub struct LawView {
    /// The tool point in the base frame (z = 0 in the plane).
    pub p: control::task::Vec3,
    /// |p_d − p| (m).
    pub tracking_error: f64,
    /// To the nearest obstacle's surface (m; negative: a link inside; +∞ without obstacles).
    pub clearance: f64,
}

/// Runs the set-up to its `[sim]` duration as the daemon runs it (steered onto a planned cycle
/// when `safety.plan` asks, the trap watch answering), handing `each` every grid state
/// k = 0 … steps, the final state at t = duration included.
pub fn run_subject(
    subject: &Subject,
    each: impl FnMut(&Visited<'_>) -> Result<()>,
) -> Result<Report> {
    Ok(run_subject_at(subject, &[], each)?.0)
}

/// [`run_subject`], with the summary a run to each of `ends` (s, at most the set-up's
/// duration) would give, from the one run.
pub fn run_subject_at(
    subject: &Subject,
    ends: &[f64],
    each: impl FnMut(&Visited<'_>) -> Result<()>,
) -> Result<(Report, Vec<Summary>)> {
    subject.run_as_daemon(SimulateRun { each, ends })
}

/// [`run_subject`]'s visitor: the run, the trap watch and the report.
struct SimulateRun<'a, F> {
    each: F,
    ends: &'a [f64],
}

impl<F: FnMut(&Visited<'_>) -> Result<()>> LoopVisitor for SimulateRun<'_, F> {
    type Out = (Report, Vec<Summary>);
    fn visit<const N: usize, L: ClosedLoopLaw<N>>(
        mut self,
        mut sim: Simulation<N, L>,
        start: Start<'_>,
    ) -> Result<Self::Out> {
        let subject = start.subject;
        let (duration, transient) = subject.duration();
        let steps = (duration / sim.dt()).round() as u64;
        let steering = sim.law.steering();
        let plan = match (&steering, &start.blocked) {
            (Some(_), _) => Some(format!(
                "steering onto a planned clean cycle (pull at {} Hz)",
                subject.plan_hz()
            )),
            (None, Some(b)) => Some(format!(
                "no clean cycle, running without steering: {}",
                b.reason
            )),
            (None, None) => None,
        };
        let mut traps = OfflineTraps::new(subject.system().clone(), steering);
        if let Some(b) = &start.blocked {
            traps.blocked_at_start(b);
        }
        let (mut k, mut failed) = (0u64, None);
        if let Some(end) = self.ends.iter().find(|&&e| !(e > 0.0 && e <= duration)) {
            bail!("a summary at {end} s of a {duration} s run: it must lie in (0, {duration}]");
        }
        let ends: Vec<f64> = std::iter::once(duration)
            .chain(self.ends.iter().copied())
            .collect();
        let mut summaries = run_steering_at(&mut sim, &ends, transient, |t, x, out| {
            if failed.is_none() {
                let law = LawView {
                    p: out.p,
                    tracking_error: out.tracking_error,
                    clearance: out.clearance,
                };
                failed = (self.each)(&visited(k, t, x, Some(law))).err();
            }
            k += 1;
            traps.observe(t, out.flags, out.tracking_error, x.q.as_slice())
        });
        if let Some(e) = failed {
            return Err(e);
        }
        let x = *sim.state();
        if !x.is_finite() {
            bail!(
                "the simulation diverged (non-finite state at t = {} s)",
                sim.time()
            );
        }
        // The final state too, at t = duration.
        (self.each)(&visited(steps, sim.time(), &x, None))?;
        let (tau, t_on) = subject.tau_and_t_on();
        let law = subject.law();
        let summary = summaries.remove(0);
        let report = Report {
            robot: subject.name(),
            model: subject.base_model(),
            n: N,
            task: subject.task_name(),
            secondary: law.secondary.name().into(),
            alpha: law.alpha,
            mu: subject.mu(),
            tau,
            t_on,
            dt: sim.dt(),
            projection: subject.feedback().projection,
            steps,
            final_time: sim.time(),
            final_q: x.q.as_slice().to_vec(),
            final_qd: x.qd.as_slice().to_vec(),
            final_phi: subject.floating().then_some(x.phi),
            steered: steering.is_some(),
            plan,
            traps: traps.events,
            summary,
        };
        Ok((report, summaries))
    }
}

pub fn run(args: SimulateArgs) -> Result<()> {
    if args.stride == 0 {
        bail!("--stride 0: must be at least 1");
    }
    let mut subject = Subject::load(&args.model.setup, args.model.mu)?;
    subject.set_duration(args.duration, args.transient)?;
    let floating = subject.floating();
    let n = subject.n();
    let mut csv = match &args.csv {
        Some(path) => {
            let f = std::fs::File::create(path)
                .with_context(|| format!("cannot create {}", path.display()))?;
            let mut w = std::io::BufWriter::new(f);
            let mut header = String::from("t");
            if floating {
                header.push_str(",phi");
            }
            for i in 1..=n {
                header.push_str(&format!(",q{i}"));
            }
            for i in 1..=n {
                header.push_str(&format!(",qd{i}"));
            }
            writeln!(w, "{header}")?;
            Some(w)
        }
        None => None,
    };
    let stride = args.stride;
    let (duration, _) = subject.duration();
    let last = (duration / subject.dt()).round() as u64;
    let report = run_subject(&subject, |v| {
        if let Some(w) = csv.as_mut() {
            if v.k % stride == 0 || v.k == last {
                write!(w, "{:.6}", v.t)?;
                if floating {
                    write!(w, ",{:.9}", v.phi)?;
                }
                for v in v.q.iter().chain(v.qd) {
                    write!(w, ",{v:.9}")?;
                }
                writeln!(w)?;
            }
        }
        Ok(())
    })?;
    if let Some(mut w) = csv {
        w.flush()?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report);
        if let Some(p) = &args.csv {
            println!(
                "  trajectory       {} (every {} steps)",
                p.display(),
                args.stride
            );
        }
    }
    Ok(())
}

fn visited<const N: usize>(k: u64, t: f64, x: &ArmState<N>, law: Option<LawView>) -> Visited<'_> {
    Visited {
        k,
        t,
        q: x.q.as_slice(),
        qd: x.qd.as_slice(),
        phi: x.phi,
        law,
    }
}

fn fmt_vec(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:+.4}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn opt(v: Option<f64>, unit: &str) -> String {
    v.map(|x| format!("{x:.4e} {unit}"))
        .unwrap_or_else(|| "n/a".into())
}

pub fn print_report(r: &Report) {
    let s = &r.summary;
    let arm = match r.model {
        Some(ModelKind::Fixed) => format!("{}-link planar arm, fixed base", r.n),
        Some(ModelKind::Floating) => format!("{}-link planar arm, floating base", r.n),
        None => format!("{} ({} joints)", r.robot, r.n),
    };
    let secondary = if r.steered {
        "none: steered onto a planned clean cycle (safety.plan)".to_string()
    } else {
        format!("{} (α = {})", r.secondary, r.alpha)
    };
    println!(
        "chaosd simulation: {arm}, {} task, secondary {secondary}, μ = {}, τ = {} s, t_on = {} s, dt = {} s{}",
        r.task,
        r.mu,
        r.tau,
        r.t_on,
        r.dt,
        if r.projection == ProjectionKind::NullSpace {
            ", feedback projected onto the null space"
        } else {
            ""
        }
    );
    println!(
        "  simulated        {:.3} s ({} steps)",
        r.final_time, r.steps
    );
    if let Some(p) = &r.plan {
        println!("  plan             {p}");
    }
    crate::traps::print(&r.traps);
    println!("  final q          [{}] rad", fmt_vec(&r.final_q));
    println!("  final q̇          [{}] rad/s", fmt_vec(&r.final_qd));
    if let Some(phi) = r.final_phi {
        println!("  final φ (base)   {phi:+.5} rad");
    }
    println!(
        "  tracking (t ≥ {:.1} s)  RMS {:.3e} m, max {:.3e} m",
        s.transient, s.rms_tracking_error, s.max_tracking_error
    );
    if s.max_orientation_error > 0.0 {
        println!("  orientation err  max {:.3e} rad", s.max_orientation_error);
    }
    if s.track_lost_fraction > 0.0 {
        println!(
            "  TRACKING LOST    {:.1}% of the time after the transient (first at t = {:.2} s); singular {:.1}%, target out of reach {:.1}%",
            100.0 * s.track_lost_fraction,
            s.first_track_loss.unwrap_or(f64::NAN),
            100.0 * s.singular_fraction,
            100.0 * s.out_of_reach_fraction
        );
    }
    println!(
        "  period residual  mean |q̇(t) − q̇(t−T)|: before feedback {}, last 10 periods {}",
        opt(s.period_residual_before, "rad/s"),
        opt(s.period_residual_final, "rad/s")
    );
    println!(
        "  stroboscopic     |x(kT) − x((k−1)T)| at the end: {}",
        opt(s.strobe_return, "")
    );
    println!(
        "  joint drift      {} per period (last two periods)",
        opt(s.drift_per_period, "rad")
    );
    let verdict = match s.period_residual_final {
        Some(v) if v < 1e-6 => "periodic with period T (residual < 1e-6)",
        Some(v) if v < 1e-3 => "close to period T",
        Some(_) => "not periodic with period T",
        None => "run too short to judge periodicity",
    };
    println!("  verdict          {verdict}");
    if let Some(c) = s.min_clearance {
        println!(
            "  obstacles        min clearance {c:+.4} m, {:.2} s inside a safety zone (r + margin)",
            s.time_in_safety_zone
        );
        println!(
            "                   {:.3} s in contact (clearance < 0), {:.3} s closer than the required {} m{}",
            s.time_in_contact.unwrap_or(0.0),
            s.time_inside_clearance.unwrap_or(0.0),
            s.required_clearance,
            if s.start_in_contact == Some(true) {
                match (s.first_clear, s.min_clearance_after_clear) {
                    (Some(t), Some(c)) => format!(
                        "; started inside an obstacle, clear from t = {t:.3} s, then min clearance {c:+.4} m and {:.3} s in contact",
                        s.time_in_contact_after_clear.unwrap_or(0.0)
                    ),
                    _ => "; started inside an obstacle and never got clear".into(),
                }
            } else {
                String::new()
            }
        );
    }
    if let Some(m) = s.min_joint_margin {
        println!("  joint limits     min margin {m:+.4} rad (negative: beyond a limit)");
    }
    if s.max_speed_ratio > 0.0 {
        println!(
            "  joint speeds     fastest {:.3} rad/s (joint {}); closest to its limit: joint {} at {:.0}%",
            s.max_joint_speed,
            s.max_joint_speed_joint,
            s.max_speed_ratio_joint,
            100.0 * s.max_speed_ratio
        );
        let jerk = if s.max_jerk_ratio > 0.0 {
            format!(", {:.0}% of the jerk limit", 100.0 * s.max_jerk_ratio)
        } else {
            String::new()
        };
        println!(
            "  joint commands   max {:.0}% of the acceleration limit{jerk}",
            100.0 * s.max_accel_ratio
        );
    }
    if s.safety_enabled {
        println!(
            "  safety filter    active {:.3} s; left the null space on {} steps ({:.3} s: tracking gave way); infeasible on {} steps",
            s.safety_active_time,
            s.safety_left_null_space_steps,
            s.safety_left_null_space_time,
            s.safety_infeasible_steps
        );
    } else {
        println!("  safety filter    off");
    }
    if s.nonfinite_steps > 0 {
        println!(
            "  WARNING          {} steps produced a non-finite command (replaced by zero)",
            s.nonfinite_steps
        );
    }
}
