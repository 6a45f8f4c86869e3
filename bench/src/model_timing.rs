//! `compute`'s robot model table: `control::model` on the 7-joint Panda (`robots/panda.urdf`,
//! tip panda_link8) next to a naive dynamic-size implementation (`naive_model`), the `k` crate
//! (FK + Jacobian; it has no dynamics) and pinocchio's C++ timings on the same machine
//! (`scripts/pinocchio-timings/run.sh`, read from a JSON file when present).
//!
//! Every operation runs on 1024 random states drawn once within the Panda's joint limits (q̇ in
//! ±2 rad/s, q̈ in ±5 rad/s², τ in ±0.5·effort), one state per call, timed per call in batches (a
//! clock read costs more than a short call), the implementations interleaved in rounds so that
//! they see the same load; percentiles are over batches. The pinocchio harness does the same.
//! Allocations are counted per call with `rt::alloc_count` (the binary's global allocator).

use crate::naive_model::NaiveModel;
use crate::report::Report;
use crate::stats::{fmt_ns, histogram, summary, Table};
use anyhow::{anyhow, Context, Result};
use control::model::{builtin, Chain, Model, TipKinematics};
use hdrhistogram::Histogram;
use nalgebra::{DVector, SVector};
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

/// The robot: the Panda.
const ROBOT: &str = "panda";
const N: usize = 7;
const STATES: usize = 1024;

/// Targets on p50 (issue 22): operation key → ns.
const TARGETS: [(&str, f64); 4] = [
    ("kin", 350.0),
    ("rnea", 500.0),
    ("crba", 350.0),
    ("aba", 1000.0),
];

/// One random state, in every form the implementations take.
pub struct State {
    pub q: SVector<f64, N>,
    pub qd: SVector<f64, N>,
    pub qdd: SVector<f64, N>,
    pub tau: SVector<f64, N>,
    pub dq: DVector<f64>,
    pub dqd: DVector<f64>,
    pub dqdd: DVector<f64>,
    pub dtau: DVector<f64>,
}

/// splitmix64, uniform in [0, 1).
fn uniform(seed: &mut u64) -> f64 {
    *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// `n` random states within the chain's position limits (continuous joints: ±π).
pub fn states(chain: &Chain, n: usize, seed: u64) -> Vec<State> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            let mut q = SVector::<f64, N>::zeros();
            let mut qd = SVector::<f64, N>::zeros();
            let mut qdd = SVector::<f64, N>::zeros();
            let mut tau = SVector::<f64, N>::zeros();
            for (i, j) in chain.joints.iter().enumerate() {
                let (lo, hi) = if j.limits.lower.is_finite() && j.limits.upper.is_finite() {
                    (j.limits.lower, j.limits.upper)
                } else {
                    (-std::f64::consts::PI, std::f64::consts::PI)
                };
                q[i] = lo + (hi - lo) * uniform(&mut s);
                qd[i] = -2.0 + 4.0 * uniform(&mut s);
                qdd[i] = -5.0 + 10.0 * uniform(&mut s);
                let effort = if j.limits.effort.is_finite() && j.limits.effort > 0.0 {
                    j.limits.effort
                } else {
                    20.0
                };
                tau[i] = (uniform(&mut s) - 0.5) * effort;
            }
            let d = |v: &SVector<f64, N>| DVector::from_column_slice(v.as_slice());
            State {
                dq: d(&q),
                dqd: d(&qd),
                dqdd: d(&qdd),
                dtau: d(&tau),
                q,
                qd,
                qdd,
                tau,
            }
        })
        .collect()
}

/// The Panda as chaosd loads it.
pub fn panda() -> Result<Chain> {
    Chain::from_urdf(builtin(ROBOT)?, None, None)
        .with_context(|| format!("cannot load the built-in {ROBOT}"))
}

/// The `k` crate's view of the same URDF: a serial chain from the root to the tip link.
#[cfg(feature = "k-crate")]
pub mod kchain {
    use anyhow::{anyhow, Result};

    pub struct KArm {
        pub arm: k::SerialChain<f64>,
    }

    impl KArm {
        pub fn new(urdf: &str, tip_link: &str) -> Result<Self> {
            let robot = urdf_rs::read_from_string(urdf)
                .map_err(|e| anyhow!("urdf-rs cannot read the URDF: {e}"))?;
            let chain = k::Chain::<f64>::from(robot);
            let end = chain
                .find_link(tip_link)
                .ok_or_else(|| anyhow!("k finds no link {tip_link}"))?;
            Ok(Self {
                arm: k::SerialChain::from_end(end),
            })
        }

        /// FK + Jacobian as a `k` user writes it: set the joints, update the transforms (the
        /// tip is the last), the tip's Jacobian. Returns the tip position and the Jacobian.
        pub fn fk_jacobian(&self, q: &[f64]) -> ([f64; 3], k::nalgebra::DMatrix<f64>) {
            self.arm
                .set_joint_positions(q)
                .expect("states are within the limits");
            let transforms = self.arm.update_transforms();
            let jac = k::jacobian(&self.arm);
            let t = transforms
                .last()
                .expect("a chain has nodes")
                .translation
                .vector;
            ([t.x, t.y, t.z], jac)
        }
    }
}

/// What the timed loop measures: per-call ns of `batches` batches of `batch` calls.
fn record(
    h: &mut Histogram<u64>,
    batches: usize,
    batch: usize,
    next: &mut usize,
    f: &mut dyn FnMut(usize),
) {
    for _ in 0..batches {
        let t0 = Instant::now();
        for i in 0..batch {
            f((*next + i) % STATES);
        }
        let ns = t0.elapsed().as_nanos() as u64 / batch as u64;
        h.saturating_record(ns.max(1));
        *next = (*next + batch) % STATES;
    }
}

/// Allocations per call of `f` over the states (`None` when the counter cannot count: the
/// counting allocator is not installed).
fn allocations(f: &mut dyn FnMut(usize)) -> Option<f64> {
    let probe = rt::alloc_count::allocations(|| {
        black_box(Vec::<u8>::with_capacity(black_box(64)));
    });
    if probe == 0 {
        return None;
    }
    let calls = 256;
    let n = rt::alloc_count::allocations(|| {
        for i in 0..calls {
            f(i % STATES);
        }
    });
    Some(n as f64 / calls as f64)
}

/// An operation of the table: its key, its title, and pinocchio's rows for it (key, what).
type Op = (
    &'static str,
    &'static str,
    &'static [(&'static str, &'static str)],
);

/// One timed series.
struct Series<'a> {
    op: &'static str,
    who: &'static str,
    label: String,
    /// Calls per batch and batches per round.
    batch: usize,
    batches: usize,
    f: Box<dyn FnMut(usize) + 'a>,
    h: Histogram<u64>,
    /// p50 of each round alone: how much the machine's load moved during the run.
    round_p50: Vec<u64>,
    allocs: Option<f64>,
}

impl<'a> Series<'a> {
    /// chaosd's fixed-size call: 100 calls per batch.
    fn chaosd(
        op: &'static str,
        label: &str,
        batches: usize,
        f: Box<dyn FnMut(usize) + 'a>,
    ) -> Self {
        Self::new(op, "chaosd", label, 100, batches, f)
    }

    /// The naive implementation, ~20× slower: 10 calls per batch.
    fn naive(op: &'static str, label: &str, batches: usize, f: Box<dyn FnMut(usize) + 'a>) -> Self {
        Self::new(op, "naive", label, 10, batches, f)
    }

    fn new(
        op: &'static str,
        who: &'static str,
        label: &str,
        batch: usize,
        batches: usize,
        f: Box<dyn FnMut(usize) + 'a>,
    ) -> Self {
        Self {
            op,
            who,
            label: label.to_string(),
            batch,
            batches,
            f,
            h: histogram(),
            round_p50: Vec::new(),
            allocs: None,
        }
    }
}

/// pinocchio's timings, from the JSON file `run.sh` writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Pinocchio {
    pub version: String,
    pub flags: String,
    pub template_instantiation: bool,
    pub cpu: String,
    /// key → (label, [p50, p90, p99, p99.9, max] ns)
    pub rows: Vec<(String, String, [f64; 5])>,
}

impl Pinocchio {
    pub fn parse(text: &str) -> Result<Self> {
        let v: serde_json::Value = serde_json::from_str(text)?;
        let s = |k: &str| v[k].as_str().unwrap_or("?").to_string();
        if v["dof"].as_u64() != Some(N as u64) || v["tip"].as_str() != Some("panda_link8") {
            return Err(anyhow!(
                "the timings are for {} joints, tip {}, not the Panda's 7 to panda_link8",
                v["dof"],
                v["tip"]
            ));
        }
        let rows = v["rows"]
            .as_object()
            .ok_or_else(|| anyhow!("no \"rows\" object"))?
            .iter()
            .map(|(k, r)| {
                let g = |f: &str| {
                    r[f].as_f64()
                        .ok_or_else(|| anyhow!("row {k} has no number {f}"))
                };
                Ok((
                    k.clone(),
                    r["label"].as_str().unwrap_or(k).to_string(),
                    [
                        g("p50_ns")?,
                        g("p90_ns")?,
                        g("p99_ns")?,
                        g("p999_ns")?,
                        g("max_ns")?,
                    ],
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            version: s("pinocchio_version"),
            flags: s("flags"),
            template_instantiation: v["template_instantiation"].as_bool().unwrap_or(false),
            cpu: s("cpu"),
            rows,
        })
    }

    fn row(&self, key: &str) -> Option<&(String, String, [f64; 5])> {
        self.rows.iter().find(|r| r.0 == key)
    }
}

/// Reads the pinocchio file: `Ok(None)` when it is not there.
fn read_pinocchio(path: &Path) -> Result<Option<Pinocchio>> {
    match std::fs::read_to_string(path) {
        Ok(text) => Pinocchio::parse(&text)
            .map(Some)
            .with_context(|| format!("cannot use {}", path.display())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e).with_context(|| format!("cannot read {}", path.display())),
    }
}

fn fmt_allocs(a: Option<f64>) -> String {
    match a {
        None => "n/a (no counter)".into(),
        Some(a) if a == a.round() => format!("{a:.0}"),
        Some(a) => format!("{a:.1}"),
    }
}

/// Times the model, writes its `.hgrm` files and returns its table and notes.
pub fn section(
    quick: bool,
    pinocchio: &crate::pinocchio_run::Timings,
    report: &mut Report,
) -> Result<String> {
    let mut text = String::new();
    let chain = panda()?;
    let model: Model<N> = chain.model::<N>()?;
    let naive = NaiveModel::new(&chain);
    let xs = states(&chain, STATES, 2026);
    #[cfg(feature = "k-crate")]
    let karm = kchain::KArm::new(builtin(ROBOT)?, &chain.tip)?;
    let pin = match &pinocchio.path {
        Some(p) => read_pinocchio(p)?,
        None => None,
    };

    // (rounds, chaosd batches per round, naive batches per round); 100 calls per chaosd batch.
    let (rounds, fast, slow) = if quick { (2, 100, 10) } else { (10, 1000, 100) };
    let mut tk = TipKinematics::<N>::default();
    let mut series: Vec<Series> = Vec::new();
    let (m, nv, x) = (&model, &naive, &xs);
    series.push(Series::chaosd(
        "kin",
        "chaosd `tip_kinematics` (fixed size)",
        fast,
        Box::new(move |i| {
            m.tip_kinematics(&x[i].q, &x[i].qd, &mut tk);
            black_box(&tk);
        }),
    ));
    series.push(Series::naive(
        "kin",
        "naive (DMatrix, 4×4 Rodrigues, J̇ as a matrix)",
        slow,
        Box::new(move |i| {
            black_box(nv.tip_kinematics(&x[i].dq, &x[i].dqd));
        }),
    ));
    #[cfg(feature = "k-crate")]
    {
        let ka = &karm;
        series.push(Series::new(
            "fkj",
            "k",
            "k 0.32: set_joint_positions + update_transforms + jacobian",
            20,
            fast / 2,
            Box::new(move |i| {
                black_box(ka.fk_jacobian(x[i].dq.as_slice()));
            }),
        ));
    }
    series.push(Series::chaosd(
        "rnea",
        "chaosd `rnea`",
        fast,
        Box::new(move |i| {
            black_box(m.rnea(&x[i].q, &x[i].qd, &x[i].qdd));
        }),
    ));
    series.push(Series::naive(
        "rnea",
        "naive (body-frame Featherstone, 6×6 DMatrix)",
        slow,
        Box::new(move |i| {
            black_box(nv.rnea(&x[i].dq, &x[i].dqd, &x[i].dqdd));
        }),
    ));
    series.push(Series::chaosd(
        "crba",
        "chaosd `mass_matrix`",
        fast,
        Box::new(move |i| {
            black_box(m.mass_matrix(&x[i].q));
        }),
    ));
    series.push(Series::naive(
        "crba",
        "naive (n + 1 RNEA columns)",
        slow,
        Box::new(move |i| {
            black_box(nv.mass_matrix(&x[i].dq));
        }),
    ));
    series.push(Series::chaosd(
        "aba",
        "chaosd `aba`",
        fast,
        Box::new(move |i| {
            black_box(m.aba(&x[i].q, &x[i].qd, &x[i].tau));
        }),
    ));
    series.push(Series::naive(
        "aba",
        "naive (M⁻¹(τ − h) by LU)",
        slow,
        Box::new(move |i| {
            black_box(nv.aba(&x[i].dq, &x[i].dqd, &x[i].dtau));
        }),
    ));
    series.push(Series::chaosd(
        "gravity",
        "chaosd `gravity_torques`",
        fast,
        Box::new(move |i| {
            black_box(m.gravity_torques(&x[i].q));
        }),
    ));
    series.push(Series::naive(
        "gravity",
        "naive (RNEA at rest)",
        slow,
        Box::new(move |i| {
            black_box(nv.gravity_torques(&x[i].dq));
        }),
    ));

    // Warm-up and allocation counts, then the interleaved rounds.
    let mut next = 0;
    for s in series.iter_mut() {
        let mut warm = histogram();
        record(&mut warm, s.batches / 10 + 1, s.batch, &mut next, &mut *s.f);
        s.allocs = allocations(&mut *s.f);
    }
    for _ in 0..rounds {
        for s in series.iter_mut() {
            let mut h = histogram();
            record(&mut h, s.batches, s.batch, &mut next, &mut *s.f);
            s.round_p50.push(h.value_at_quantile(0.5));
            s.h.add(&h).map_err(|e| anyhow!("{e}"))?;
        }
    }

    let p50 = |op: &str, who: &str| {
        series
            .iter()
            .find(|s| s.op == op && s.who == who)
            .map(|s| summary(&s.h)[0] as f64)
    };
    let mut table = Table::new(&[
        "operation",
        "implementation",
        "p50",
        "p90",
        "p99",
        "p99.9",
        "max",
        "allocations / call",
        "vs chaosd (p50)",
        "target (p50)",
    ]);
    let ops: [Op; 5] = [
        (
            "kin",
            "FK + tip Jacobian + J̇q̇",
            &[
                (
                    "fk_jacobian_jdot_qd",
                    "FK(q, q̇, 0) + joint Jacobians + frame Jacobian + classical acceleration",
                ),
                ("fk_jacobian", "FK + Jacobian only"),
                (
                    "fk_jdot_qd",
                    "FK(q, q̇, 0) + classical acceleration (J̇q̇) only",
                ),
            ],
        ),
        ("rnea", "RNEA τ(q, q̇, q̈)", &[("rnea", "")]),
        (
            "crba",
            "CRBA M(q)",
            &[
                ("crba", "default (LOCAL) convention"),
                ("crba_world", "Convention::WORLD"),
            ],
        ),
        (
            "aba",
            "ABA q̈(q, q̇, τ)",
            &[
                ("aba", "default (LOCAL) convention"),
                ("aba_world", "Convention::WORLD"),
            ],
        ),
        ("gravity", "gravity g(q)", &[("gravity", "")]),
    ];
    let mut target_lines = Vec::new();
    for (op, title, pin_rows) in ops {
        let base = p50(op, "chaosd").unwrap_or(f64::NAN);
        let mut rows_of = |s: &Series| {
            let v = summary(&s.h);
            let target = TARGETS.iter().find(|t| t.0 == op && s.who == "chaosd");
            let target_cell = match target {
                Some((_, t)) => {
                    let met = (v[0] as f64) <= *t;
                    target_lines.push(format!(
                        "{title}: p50 {} (target ≤ {}): **{}**",
                        fmt_ns(v[0] as f64),
                        fmt_ns(*t),
                        if met { "met" } else { "MISSED" }
                    ));
                    format!("≤ {}: {}", fmt_ns(*t), if met { "met" } else { "MISSED" })
                }
                None => String::new(),
            };
            let ratio = if s.who == "chaosd" {
                "1.0×".to_string()
            } else {
                format!("{:.1}×", v[0] as f64 / base)
            };
            table.row(vec![
                title.to_string(),
                s.label.clone(),
                fmt_ns(v[0] as f64),
                fmt_ns(v[1] as f64),
                fmt_ns(v[2] as f64),
                fmt_ns(v[3] as f64),
                fmt_ns(v[4] as f64),
                fmt_allocs(s.allocs),
                ratio,
                target_cell,
            ]);
        };
        for s in series.iter().filter(|s| s.op == op) {
            rows_of(s);
        }
        if op == "kin" {
            for s in series.iter().filter(|s| s.op == "fkj") {
                let v = summary(&s.h);
                table.row(vec![
                    "FK + tip Jacobian (no J̇q̇)".into(),
                    s.label.clone(),
                    fmt_ns(v[0] as f64),
                    fmt_ns(v[1] as f64),
                    fmt_ns(v[2] as f64),
                    fmt_ns(v[3] as f64),
                    fmt_ns(v[4] as f64),
                    fmt_allocs(s.allocs),
                    format!("{:.1}× (chaosd also does J̇q̇)", v[0] as f64 / base),
                    String::new(),
                ]);
            }
            #[cfg(not(feature = "k-crate"))]
            table.row(vec![
                "FK + tip Jacobian (no J̇q̇)".into(),
                "k 0.32: not built (cargo feature `k-crate`)".into(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ]);
        }
        for (key, what) in pin_rows {
            // The kinematics' partial rows do less than chaosd's row: say so.
            let (title, less) = match *key {
                "fk_jacobian" => ("FK + tip Jacobian (no J̇q̇)", " (chaosd also does J̇q̇)"),
                "fk_jdot_qd" => ("FK(q, q̇, 0) + J̇q̇ (no Jacobian)", " (chaosd also does J)"),
                _ => (title, ""),
            };
            let label = |p: &Pinocchio| {
                format!(
                    "pinocchio {}{}{}",
                    p.version,
                    if what.is_empty() { "" } else { ": " },
                    what
                )
            };
            match pin.as_ref().map(|p| (p, p.row(key))) {
                Some((p, Some((_, _, v)))) => table.row(vec![
                    title.to_string(),
                    label(p),
                    fmt_ns(v[0]),
                    fmt_ns(v[1]),
                    fmt_ns(v[2]),
                    fmt_ns(v[3]),
                    fmt_ns(v[4]),
                    "(C++)".into(),
                    format!("{:.1}×{less}", v[0] / base),
                    String::new(),
                ]),
                Some((p, None)) => table.row(vec![
                    title.to_string(),
                    format!("{}: no row {key} in the file", label(p)),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                ]),
                None if *key == pin_rows[0].0 => table.row(vec![
                    title.to_string(),
                    format!("pinocchio: {}", pinocchio.why_not),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                    String::new(),
                ]),
                None => {}
            }
        }
    }
    for s in &series {
        report.hgrm(&format!("model-{}-{}", s.op, s.who), &s.h)?;
    }

    text.push_str(&format!(
        "\n### Robot model: the {N}-joint Panda (`robots/panda.urdf`, tip panda_link8)\n\n\
         {STATES} random states within the joint limits, one per call, timed per call in batches \
         (chaosd 100 calls, naive 10, k 20), implementations interleaved over {rounds} rounds; \
         percentiles over batches. Allocations counted per call (`rt::alloc_count`).\n\n"
    ));
    text.push_str(&table.render());
    match &pin {
        Some(p) => text.push_str(&format!(
            "\npinocchio {} ({}{}) on {}, {}, by its own harness \
             (scripts/pinocchio-timings/run.sh) with the same method; its CRBA fills the upper \
             triangle only, chaosd's the whole matrix.\n",
            p.version,
            p.flags,
            if p.template_instantiation {
                ", the wheel's precompiled algorithms"
            } else {
                ", compiled from its headers"
            },
            p.cpu,
            match (&pinocchio.path, pinocchio.this_run) {
                (Some(f), true) => format!(
                    "timed in this run just before chaosd's rows, on the same core ({})",
                    f.display()
                ),
                (Some(f), false) => format!("read from {} (another run)", f.display()),
                (None, _) => String::new(),
            }
        )),
        None => text.push_str(&format!(
            "\npinocchio: {} (`compute` times it with scripts/pinocchio-timings/run.sh when \
             Python and a C++ compiler are here; `--pinocchio FILE` reads another run's).\n",
            pinocchio.why_not
        )),
    }
    let spread: Vec<String> = series
        .iter()
        .map(|s| {
            let lo = s.round_p50.iter().min().copied().unwrap_or(0);
            let hi = s.round_p50.iter().max().copied().unwrap_or(0);
            format!(
                "{} {} {}–{}",
                s.who,
                s.op,
                fmt_ns(lo as f64),
                fmt_ns(hi as f64)
            )
        })
        .collect();
    text.push_str(&format!(
        "p50 of each round alone, lowest–highest (the machine's load moves; the interleaved \
         implementations move together): {}\n",
        spread.join(", ")
    ));
    text.push_str(&format!(
        "Targets (Panda, p50): {}\n",
        target_lines.join("; ")
    ));
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_are_within_the_limits_and_differ() {
        let chain = panda().unwrap();
        let xs = states(&chain, 64, 1);
        for x in &xs {
            for (i, j) in chain.joints.iter().enumerate() {
                assert!(x.q[i] >= j.limits.lower && x.q[i] <= j.limits.upper);
                assert!(x.qd[i].abs() <= 2.0 && x.qdd[i].abs() <= 5.0);
                assert!(x.tau[i].abs() <= 0.5 * j.limits.effort);
                assert_eq!(x.dq[i], x.q[i]);
            }
        }
        assert_ne!(xs[0].q, xs[1].q);
    }

    #[test]
    fn pinocchio_files_are_read_and_checked() {
        let text = r#"{"pinocchio_version": "4.1.0", "flags": "-O3", "template_instantiation": false,
            "cpu": "x", "tip": "panda_link8", "dof": 7,
            "rows": {"rnea": {"label": "RNEA", "p50_ns": 980.0, "p90_ns": 1000.0, "p99_ns": 1100.0,
                              "p999_ns": 1200.0, "max_ns": 5000.0}}}"#;
        let p = Pinocchio::parse(text).unwrap();
        assert_eq!(p.version, "4.1.0");
        assert_eq!(p.row("rnea").unwrap().2[0], 980.0);
        assert!(p.row("aba").is_none());
        assert!(Pinocchio::parse(&text.replace("\"dof\": 7", "\"dof\": 6")).is_err());
        assert!(Pinocchio::parse(&text.replace("\"p99_ns\": 1100.0,", "")).is_err());
        assert!(read_pinocchio(Path::new("/nonexistent/pinocchio.json"))
            .unwrap()
            .is_none());
    }

    #[cfg(feature = "k-crate")]
    #[test]
    fn k_agrees_with_chaosd_on_the_tip() {
        let chain = panda().unwrap();
        let model: Model<N> = chain.model().unwrap();
        let karm = kchain::KArm::new(builtin(ROBOT).unwrap(), &chain.tip).unwrap();
        let mut tk = TipKinematics::default();
        for x in states(&chain, 8, 3) {
            model.tip_kinematics(&x.q, &x.qd, &mut tk);
            let (p, j) = karm.fk_jacobian(x.dq.as_slice());
            for r in 0..3 {
                assert!((p[r] - tk.frames.tip.pos[r]).abs() < 1e-9, "{p:?}");
            }
            for r in 0..6 {
                for c in 0..N {
                    assert!((j[(r, c)] - tk.jacobian[(r, c)]).abs() < 1e-9, "{j}");
                }
            }
        }
    }
}
