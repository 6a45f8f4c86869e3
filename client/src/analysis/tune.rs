//! `chaosctl tune`: the Pyragas gain the daemon chooses from its model for `mu = "auto"`
//! ([`control::tune`]), offline, with every gain it tried. The daemon runs the same function
//! on its own thread at start and after every edit; this shows a user what it will choose and
//! why before a run, and is how the book validates the choice.

use crate::setup::{parse_list, FloatList, SetupArgs};
use crate::subject::Subject;
use anyhow::{bail, Result};
use clap::Args;
use control::basics::number::short;
use control::tune::{choose_gain, GainChoice, TuneSpec};

#[derive(Args, Debug)]
pub struct TuneCmd {
    #[command(flatten)]
    pub setup: SetupArgs,
    /// The largest gain considered (default: the set-up's max_mu, else chaosd's bound).
    #[arg(long = "max-mu", allow_hyphen_values = true)]
    pub max_mu: Option<f64>,
    /// Gains on the coarse grid over (0, max_mu], geometric from 0.02.
    #[arg(long, default_value_t = 8)]
    pub grid: usize,
    /// Golden-section steps around the best grid gain.
    #[arg(long, default_value_t = 6)]
    pub refine: usize,
    /// Start Newton's method from this state at t = kT: q then q̇, comma-separated (default:
    /// the closest return of a run of the set-up).
    #[arg(long, value_parser = parse_list, allow_hyphen_values = true)]
    pub seed: Option<FloatList>,
    /// Print the choice, the cycle and every gain tried as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: TuneCmd) -> Result<()> {
    let subject = Subject::load(&a.setup, None)?;
    let system = subject.system();
    let mut spec = TuneSpec::of(system);
    if let Some(m) = a.max_mu {
        spec.max_mu = m;
        spec.seed_mu = spec.seed_mu.min(0.5 * m);
    }
    (spec.grid, spec.refine) = (a.grid, a.refine);
    let seed = a.seed.map(|s| s.0);
    if let Some(s) = &seed {
        let want = 2 * system.n();
        if s.len() != want {
            bail!(
                "--seed: a state of this arm is q then q̇, {want} numbers, not {}",
                s.len()
            );
        }
    }
    let choice = choose_gain(system, seed.as_deref(), &spec)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&json(&choice))?);
    } else {
        print!("{}", table(&choice));
    }
    Ok(())
}

fn json(c: &GainChoice) -> serde_json::Value {
    let mut v = serde_json::to_value(c).unwrap_or_default();
    v["why"] = c.why().into();
    v["orbit"]["kind"] = c.orbit.kind().into();
    v
}

/// The cycle, every gain tried (the chosen one marked `*`, the fastest `f`) and the choice in
/// one line.
fn table(c: &GainChoice) -> String {
    let mut out = format!(
        "cycle     q = ({}) at t = kT, Newton residual {:.1e}, at μ = 0 {}\n\n",
        crate::analysis::fmt_list(&c.orbit.q),
        c.orbit.residual,
        c.orbit.kind()
    );
    out.push_str("        μ    |ρ₁| a period    rate (1/s)\n");
    for p in &c.scanned {
        let mark = match p.mu {
            mu if mu == c.mu => "*",
            mu if mu == c.fastest.mu => "f",
            _ => " ",
        };
        let unsure = if p.converged {
            ""
        } else {
            "  (Arnoldi not converged)"
        };
        out.push_str(&format!(
            "{mark} {:>8}  {:>14.4}  {:>12.3}{unsure}\n",
            short(p.mu),
            p.multiplier,
            p.rate
        ));
    }
    out.push_str(&format!("\nchosen    {}\n", c.why()));
    out
}
