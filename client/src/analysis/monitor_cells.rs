//! What one run of `chaosctl monitor` leaves: a fixed-μ cell or an auto-μ cell. A file of its
//! own so the runs (`monitor`) and the report (`monitor_report`) share them, not each other.

use control::monitor::Verdict;
use serde::Serialize;

/// What the offline analysis says of a run: λ_max beyond two standard errors either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Offline {
    Chaotic,
    Stable,
    Marginal,
    Failed,
}

/// One fixed-μ run of one start.
#[derive(Clone, Debug, Serialize)]
pub struct FixedCell {
    pub start: usize,
    pub mu: f64,
    pub lambda_max: Option<f64>,
    pub stderr: Option<f64>,
    pub offline: Offline,
    pub verdict: Verdict,
    /// Periods from the start until the monitor's first verdict (its detection delay).
    pub first_verdict_periods: Option<f64>,
    /// The first verdict it gave.
    pub first_verdict: Verdict,
    /// Periods from the start until the monitor's verdict settled on its final value (for an
    /// arm captured by the orbit, this includes the chaotic transient before capture).
    pub settled_periods: Option<f64>,
    pub effort: f64,
}

/// Which edit a robustness run makes half-way.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EditKind {
    None,
    /// The task circle's radius × 1.1.
    Radius,
    /// The task's period × 1.1, and τ with it (`set task.period … tau …`).
    Period,
    /// The first obstacle moved 5 cm along x (a config with obstacles), else none is made.
    Obstacle,
}

impl EditKind {
    /// Every kind, in the order the report lists them.
    pub const ALL: [EditKind; 4] = [
        EditKind::None,
        EditKind::Radius,
        EditKind::Period,
        EditKind::Obstacle,
    ];
}

/// One `mu = "auto"` run of one start.
#[derive(Clone, Debug, Serialize)]
pub struct AutoCell {
    pub start: usize,
    pub edit: EditKind,
    pub edit_at: Option<f64>,
    pub verdict: Verdict,
    /// When the verdict last became periodic (s), if it ended so.
    pub periodic_at: Option<f64>,
    pub mu_final: f64,
    /// μ just before the edit.
    pub mu_at_edit: Option<f64>,
    pub effort: f64,
    /// The first verdict and when it came (s).
    pub first_verdict: Option<(Verdict, f64)>,
    /// The gains the model chose, at the start and after the edit (as the daemon would).
    pub model: Vec<control::monitor::run::ModelChoice>,
    #[serde(skip)]
    pub trace: Vec<control::monitor::run::PeriodPoint>,
}

/// A start run at the best fixed gain the analysis finds for it (`control::tune`): what
/// `mu = "auto"` is measured against.
#[derive(Clone, Debug, Serialize)]
pub struct BestFixed {
    pub start: usize,
    /// The gain, or why the analysis found none.
    pub mu: Result<f64, String>,
    pub verdict: Verdict,
    pub periodic_at: Option<f64>,
    pub effort: f64,
}
