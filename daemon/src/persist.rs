//! What survives a daemon restart: the live configuration, controller time and a FAULT.
//!
//! An operator's `chaosctl set`, `obstacle` and `dfc` changes live only in the running daemon.
//! A restart (a crash, a supervisor's restart, an upgrade) must not silently revert them, restart
//! controller time at 0 (feedback off again until t_on) or clear a FAULT that nobody resumed. So
//! the reporter thread, never the loop, writes `live-state.toml` in the output directory after
//! every accepted change and once a second, atomically (a temporary file renamed over the old
//! one, mode 0600), and `chaosd run` starts from it unless told `--fresh`.
//!
//! Not kept: the delay-line history (a restarted daemon starts a fresh one, as after HOLD), the
//! histograms and counters (each run writes its own files).

use control::{ConfigError, System};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The file's name inside the output directory.
pub const FILE: &str = "live-state.toml";

/// What a restarted daemon resumes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LiveState {
    /// Controller time (s) of the newest state when this was written.
    pub t: f64,
    /// Wall-clock time (s since the Unix epoch) when this was written: a restarted daemon
    /// resumes at `t` plus the time since, so controller time keeps pace with the world.
    pub saved_unix_s: f64,
    /// The daemon was in FAULT, and why.
    pub fault: Option<String>,
    /// The running configuration (without `[daemon]` and `[plant]`, which come from the file).
    pub system: SavedSystem,
    /// [`fingerprint`] of the config file's settings the live changes were made on top of. When
    /// the file's settings differ at the next start, an operator edited the file since: the file
    /// wins (see [`adopt`]). Absent in states saved before this existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// With `mu = "auto"`: where the adaptation had taken μ, and the model's gain it was
    /// anchored on (the file says only "auto"). Absent in states saved before this existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain: Option<SavedGain>,
}

/// An adapting gain as it stood.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedGain {
    pub mu: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<f64>,
}

impl SavedGain {
    /// `system` (adapting μ) with this gain, bounded by its `max_mu`; unchanged for a fixed
    /// gain or a value that is not a gain (a hand-edited file), which the adaptation starts
    /// afresh from instead.
    pub fn restore(&self, system: &mut System) {
        let gain = |v: f64| v.is_finite() && v >= 0.0;
        let f = system.feedback_section_mut();
        let Some(auto) = f.auto.as_mut() else {
            return;
        };
        if gain(self.mu) {
            f.mu = self.mu.min(auto.max_mu);
        }
        auto.anchor = self.model.filter(|m| gain(*m)).map(|m| m.min(auto.max_mu));
    }
}

/// The saved set-up: the config file's text as [`System::to_toml`] writes it, without its
/// `[daemon]` and `[plant]` tables, kept as a TOML table (so the state file nests it). Read back
/// through [`System::parse`], as any config file: the planar arm in either of its forms or a
/// robot, whose description is read anew.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct SavedSystem(toml::Table);

impl SavedSystem {
    /// `system` without its `[daemon]` and `[plant]` tables. An error only if
    /// [`System::to_toml`] wrote text that does not read back as TOML (a bug, which the caller
    /// reports rather than saving an empty set-up a restart would refuse).
    pub fn of(system: &System) -> Result<Self, ConfigError> {
        let text = settings_text(system);
        toml::from_str(&text)
            .map(SavedSystem)
            .map_err(|e| ConfigError::Parse(format!("the running set-up as TOML: {e}")))
    }

    /// The set-up again (a robot's description is read anew), validated.
    pub fn to_system(&self) -> Result<System, ConfigError> {
        let text = toml::to_string(&self.0).map_err(|e| ConfigError::Parse(e.to_string()))?;
        System::parse(&text, &rt::robot::resolve)
    }
}

/// A config's settings as TOML, without its `[daemon]` and `[plant]` tables.
fn settings_text(system: &System) -> String {
    let mut s = system.clone();
    let (d, p) = s.tables_mut();
    (*d, *p) = (None, None);
    s.to_toml()
}

/// A stable fingerprint of a config's settings (without `[daemon]` and `[plant]`): FNV-1a 64
/// of their TOML.
pub fn fingerprint(system: &System) -> String {
    let h = settings_text(system)
        .bytes()
        .fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        });
    format!("{h:016x}")
}

/// What a start adopts from a saved state, given the settings of the config file it starts with.
/// If the file was edited since the state was saved (its fingerprint changed), the file's
/// settings win and the live changes are dropped (`Some(why)` says so); controller time and a
/// FAULT are kept either way, since neither is the file's to decide.
pub fn adopt(
    mut saved: LiveState,
    file: &System,
) -> Result<(LiveState, Option<String>), ConfigError> {
    let now = fingerprint(file);
    let edited = saved.file.as_ref().is_some_and(|f| *f != now);
    let why = if edited {
        saved.system = SavedSystem::of(file)?;
        Some(
            "the config file's settings changed since the live state was saved: starting from \
             the file (live changes made with chaosctl are dropped; controller time and any FAULT \
             are kept)"
                .to_string(),
        )
    } else {
        None
    };
    saved.file = Some(now);
    Ok((saved, why))
}

pub fn path(output_dir: &Path) -> PathBuf {
    output_dir.join(FILE)
}

/// Writes the state atomically (tmp + rename), owner-only.
pub fn save(output_dir: &Path, state: &LiveState) -> std::io::Result<()> {
    let text = toml::to_string_pretty(state).map_err(std::io::Error::other)?;
    let tmp = output_dir.join(format!("{FILE}.tmp"));
    rt::files::write(&tmp, text)?;
    std::fs::rename(&tmp, path(output_dir))
}

/// Reads a saved state; `Ok(None)` if there is none. A state that does not parse or validate,
/// or was written for an arm of another size, is an error naming the file (never ignored
/// silently: the operator decides, with `--fresh`).
pub fn load(output_dir: &Path, n: usize) -> anyhow::Result<Option<LiveState>> {
    let p = path(output_dir);
    let text = match std::fs::read_to_string(&p) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => anyhow::bail!(
            "cannot read {}: {e} (start with --fresh to ignore it)",
            p.display()
        ),
    };
    let bad =
        |why: String| anyhow::anyhow!("{}: {why} (start with --fresh to ignore it)", p.display());
    if text.len() > control::basics::MAX_CONFIG_BYTES {
        return Err(bad("too large to be a saved state".into()));
    }
    let mut s: LiveState =
        toml::from_str(&text).map_err(|e| bad(control::basics::excerpt(&e.to_string())))?;
    let system = s.system.to_system().map_err(|e| bad(e.to_string()))?;
    s.t += (unix_now() - s.saved_unix_s).clamp(0.0, 1e7);
    if system.n() != n || !s.t.is_finite() || s.t < 0.0 {
        return Err(bad(format!(
            "saved for a {}-link arm at t = {}; this configuration has {n} links",
            system.n(),
            s.t
        )));
    }
    Ok(Some(s))
}

/// Seconds since the Unix epoch.
pub fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Removes a saved state (`--fresh`).
pub fn clear(output_dir: &Path) -> std::io::Result<()> {
    match std::fs::remove_file(path(output_dir)) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control::Config;

    #[test]
    fn a_saved_state_reads_back_and_bad_ones_are_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("chaosd-persist-{}", std::process::id()));
        rt::files::create_dir_all(&dir).unwrap();
        assert_eq!(load(&dir, 3).unwrap(), None);
        let mut system = Config::preset("demo").unwrap();
        system.feedback.mu = 1.3;
        system
            .planar_mut()
            .unwrap()
            .obstacles
            .push(control::config::ObstacleConfig {
                center: [0.0, 1.6],
                radius: 0.2,
                margin: 0.1,
            });
        let s = LiveState {
            t: 123.5,
            saved_unix_s: unix_now() + 1e3, // in the future: no time added
            fault: Some("joint 2 rate".into()),
            system: SavedSystem::of(&System::Planar(system)).unwrap(),
            file: Some("0123456789abcdef".into()),
            gain: Some(SavedGain {
                mu: 0.21,
                model: Some(0.19),
            }),
        };
        save(&dir, &s).unwrap();
        assert_eq!(load(&dir, 3).unwrap(), Some(s));
        assert!(load(&dir, 4).unwrap_err().to_string().contains("3-link"));
        std::fs::write(path(&dir), "t = \"soon\"").unwrap();
        assert!(load(&dir, 3).unwrap_err().to_string().contains("--fresh"));
        clear(&dir).unwrap();
        clear(&dir).unwrap();
        assert_eq!(load(&dir, 3).unwrap(), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn mu_kv(s: &LiveState) -> (f64, f64) {
        let System::Planar(c) = s.system.to_system().unwrap() else {
            panic!("a planar state")
        };
        (c.feedback.mu, c.law.kv)
    }

    #[test]
    fn an_edited_file_wins_over_the_live_changes_but_time_and_fault_stay() {
        let file = Config::preset("demo").unwrap();
        let mut live = file.clone();
        live.feedback.mu = 1.3; // a chaosctl set on top of the file
        let file = System::Planar(file);
        let saved = LiveState {
            t: 50.0,
            saved_unix_s: unix_now(),
            fault: Some("joint 2 rate".into()),
            system: SavedSystem::of(&System::Planar(live.clone())).unwrap(),
            file: Some(fingerprint(&file)),
            gain: None,
        };
        // The same file: the live change is resumed.
        let (s, why) = adopt(saved.clone(), &file).unwrap();
        assert_eq!((mu_kv(&s).0, why), (1.3, None));
        // The file edited since (another kv): its settings win, time and FAULT stay.
        let mut edited = file.clone();
        let System::Planar(c) = &mut edited else {
            unreachable!()
        };
        c.law.kv = 30.0;
        let (s, why) = adopt(saved.clone(), &edited).unwrap();
        assert!(why.unwrap().contains("changed since"));
        assert_eq!(mu_kv(&s), (file.feedback().mu, 30.0));
        assert_eq!((s.t, s.fault.as_deref()), (50.0, Some("joint 2 rate")));
        assert_eq!(s.file, Some(fingerprint(&edited)));
        // A state saved before fingerprints existed: resumed as it is.
        let old = LiveState {
            file: None,
            ..saved
        };
        assert_eq!(mu_kv(&adopt(old, &edited).unwrap().0).0, 1.3);
    }

    #[test]
    fn an_adapting_gain_and_its_anchor_survive_a_restart() {
        let mut auto = System::preset("paper", &rt::robot::resolve).unwrap();
        auto.schedule_feedback(control::adapt::MuSetting::Auto, 0.0);
        let g = SavedGain {
            mu: 0.27,
            model: Some(0.23),
        };
        let mut back = auto.clone();
        g.restore(&mut back);
        let fb = back.feedback();
        assert_eq!((fb.mu, fb.auto.unwrap().anchor), (0.27, Some(0.23)));
        // Bounded by max_mu; a value that is no gain is not adopted.
        let mut back = auto.clone();
        SavedGain {
            mu: 9.0,
            model: Some(f64::NAN),
        }
        .restore(&mut back);
        let fb = back.feedback();
        assert_eq!(
            (fb.mu, fb.auto.unwrap().anchor),
            (fb.auto.unwrap().max_mu, None)
        );
        // A fixed gain is the file's: left as it is.
        let fixed = System::preset("paper", &rt::robot::resolve).unwrap();
        let mut back = fixed.clone();
        g.restore(&mut back);
        assert_eq!(back, fixed);
    }

    /// States saved by the daemon of November 2026, when the planar set-up was kept in its
    /// older table form: a restart after an upgrade resumes them.
    #[test]
    fn states_saved_by_an_older_daemon_still_load() {
        let planar: LiveState = toml::from_str(include_str!(
            "../tests/fixtures/live-state-planar-2026-11.toml"
        ))
        .unwrap();
        let mut want = Config::preset("demo").unwrap();
        want.feedback.mu = 1.3;
        assert_eq!(planar.system.to_system().unwrap(), System::Planar(want));
        let panda: LiveState = toml::from_str(include_str!(
            "../tests/fixtures/live-state-panda-2026-11.toml"
        ))
        .unwrap();
        let want = rt::robot::preset("panda").unwrap();
        assert_eq!(panda.system.to_system().unwrap(), want);
        assert_eq!(
            fingerprint(&panda.system.to_system().unwrap()),
            fingerprint(&want)
        );
    }

    #[test]
    fn a_spatial_state_reads_back_as_a_spatial_system() {
        let dir = std::env::temp_dir().join(format!("chaosd-persist-sp-{}", std::process::id()));
        rt::files::create_dir_all(&dir).unwrap();
        let mut panda = rt::robot::preset("panda").unwrap();
        let System::Spatial(b) = &mut panda else {
            unreachable!()
        };
        b.config.feedback.mu = 0.4;
        let s = LiveState {
            t: 9.0,
            saved_unix_s: unix_now() + 1e3,
            fault: None,
            system: SavedSystem::of(&panda).unwrap(),
            file: Some(fingerprint(&panda)),
            gain: None,
        };
        save(&dir, &s).unwrap();
        let back = load(&dir, 7).unwrap().unwrap();
        assert_eq!(back, s);
        assert_eq!(back.system.to_system().unwrap().feedback().mu, 0.4);
        assert!(load(&dir, 3).unwrap_err().to_string().contains("7-link"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
