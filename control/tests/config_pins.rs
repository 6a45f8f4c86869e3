//! What a config is, pinned before the two config types become one (docs/plans/one-config.md,
//! stage 0): every preset's printed file, its law's whole parameter block (Debug prints each
//! f64 in its shortest round-trip form: on one machine, equal text is equal bits), the
//! fingerprint a planar shard grid carries, and the exact message of a set of bad files in each
//! of the three file forms.
//!
//! The fixtures under `tests/fixtures/config/` were written by this test on 6818c95. A change
//! that means to change one of them writes them again with `CHAOSD_BLESS=1` and says why in its
//! commit; any other change must leave every one byte for byte as it is.

use control::system::builtin_robot;
use control::System;
use std::path::PathBuf;

const PRESETS: &[&str] = &[
    "paper",
    "paper-eq11",
    "paper-obstacle",
    "paper-floating",
    "demo",
    "panda",
    "panda-paper",
];

/// Bad files, each named, in the three forms: the older planar one (`[arm]`, `[control]`), the
/// shared planar one (`[robot] description = "planar"`) and a robot's.
const BAD: &[(&str, &str)] = &[
    ("older: unknown table", "[arm]\nlinks = [1.0, 1.0, 1.0]\n[wheels]\nx = 1\n"),
    ("older: unknown key in control", "[control]\nkpp = 1.0\n"),
    ("older: wrong type", "[control]\nkp = \"stiff\"\n"),
    ("older: negative radius", "[task]\nradius = -1.0\n"),
    ("older: no links", "[arm]\nlinks = []\n"),
    ("older: thirteen links", "[arm]\nlinks = [1,1,1,1,1,1,1,1,1,1,1,1,1]\n"),
    ("older: start of the wrong size", "[sim]\nq0 = [0.1, 0.2]\n"),
    ("older: tau beyond max_tau", "[feedback]\ntau = 5.0\nmax_tau = 2.0\n"),
    (
        "older: obstacle of negative radius",
        "[[control.obstacles]]\ncenter = [0.0, 1.6]\nradius = -0.1\n",
    ),
    (
        "older: a start too far out to move",
        "[sim]\nq0 = [0.0, 1e300, 1.0]\n",
    ),
    (
        "planar: misspelt key",
        "[robot]\ndescription = \"planar\"\nlnks = [1.0, 1.0, 1.0]\n",
    ),
    (
        "planar: a command section",
        "[robot]\ndescription = \"planar\"\n[command]\nmode = \"position\"\n",
    ),
    (
        "planar: obstacles under law",
        "[robot]\ndescription = \"planar\"\n[[law.obstacles]]\ncenter = [0.0, 1.6]\nradius = 0.2\n",
    ),
    (
        "planar: bad gain on line 3",
        "[robot]\ndescription = \"planar\"\n[law]\nkp = \"x\"\n",
    ),
    (
        "robot: no sim",
        "[robot]\ndescription = \"panda\"\n[task]\nkind = \"position\"\npath = \"circle\"\nnormal = [0.0, 0.0, 1.0]\nradius = 0.1\nperiod = 2.0\n",
    ),
    (
        "robot: unknown robot",
        "[robot]\ndescription = \"ur10\"\n[task]\nkind = \"position\"\npath = \"circle\"\nnormal = [0.0, 0.0, 1.0]\nradius = 0.1\nperiod = 2.0\n[sim]\nq0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]\n",
    ),
    (
        "robot: unknown key",
        "[robot]\ndescription = \"panda\"\nwheels = 4\n",
    ),
    (
        "robot: task sideways",
        "[robot]\ndescription = \"panda\"\n[task]\nkind = \"sideways\"\npath = \"circle\"\nnormal = [0.0, 0.0, 1.0]\nradius = 0.1\nperiod = 2.0\n[sim]\nq0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]\n",
    ),
    (
        "robot: start of the wrong size",
        "[robot]\ndescription = \"panda\"\n[task]\nkind = \"position\"\npath = \"circle\"\nnormal = [0.0, 0.0, 1.0]\nradius = 0.1\nperiod = 2.0\n[sim]\nq0 = [0.0, 0.1]\n",
    ),
    (
        "robot: a start speed too large to be one",
        "[robot]\ndescription = \"panda\"\n[task]\nkind = \"position\"\npath = \"circle\"\nnormal = [0.0, 0.0, 1.0]\nradius = 0.1\nperiod = 2.0\n[sim]\nq0 = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]\nqd0 = [1e300, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n",
    ),
];

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/config")
}

/// Compares `text` with the fixture `name`, or writes it with `CHAOSD_BLESS=1`.
fn pinned(name: &str, text: &str) {
    let path = fixtures().join(name);
    if std::env::var_os("CHAOSD_BLESS").is_some() {
        std::fs::create_dir_all(fixtures()).unwrap();
        std::fs::write(&path, text).unwrap();
        return;
    }
    let want = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (CHAOSD_BLESS=1 writes it)", path.display()));
    assert!(
        want == text,
        "{} changed:\n--- pinned\n{want}\n--- now\n{text}",
        path.display()
    );
}

/// Compares `text` with the fixture `name` number by number: the same words and punctuation,
/// and every number within 1e-12 of the pinned one (relative above 1). A robot's block holds
/// numbers the C library's `sin` and `cos` computed (the task's centre where the tool starts),
/// which another machine's libm may round one bit apart; on one machine the text is the same to
/// the byte.
fn pinned_numbers(name: &str, text: &str) {
    let path = fixtures().join(name);
    if std::env::var_os("CHAOSD_BLESS").is_some() {
        return pinned(name, text);
    }
    let want = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (CHAOSD_BLESS=1 writes it)", path.display()));
    let (a, b) = (tokens(&want), tokens(text));
    let same = a.len() == b.len()
        && a.iter()
            .zip(&b)
            .all(|(x, y)| match (x.parse::<f64>(), y.parse::<f64>()) {
                (Ok(x), Ok(y)) => x == y || (x - y).abs() <= 1e-12 * x.abs().max(1.0),
                _ => x == y,
            });
    assert!(
        same,
        "{} changed:\n--- pinned\n{want}\n--- now\n{text}",
        path.display()
    );
}

/// The text cut into numbers and the runs between them.
fn tokens(text: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut number = false;
    for c in text.chars() {
        let digit = c.is_ascii_digit() || (number && matches!(c, '.' | 'e' | '-' | '+'));
        let starts = c.is_ascii_digit() || c == '-';
        match out.last_mut() {
            Some(t) if digit == number && (digit || !starts) => t.push(c),
            _ => {
                number = starts;
                out.push(c.to_string());
            }
        }
    }
    out
}

/// FNV-1a, 64 bits: a long text's fingerprint in one line.
fn fnv(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

#[test]
fn every_preset_prints_and_runs_as_pinned() {
    let mut prints = String::new();
    for name in PRESETS {
        let s = System::preset(name, &builtin_robot).unwrap();
        let text = s.to_toml();
        pinned(&format!("{name}.toml"), &text);
        pinned_numbers(
            &format!("{name}.block.txt"),
            &format!("{:#?}\n", s.param_block()),
        );
        // A robot's fingerprint holds its chain's rotations (libm's `sin`, `cos`): planar only.
        if s.chain().is_none() {
            prints.push_str(&format!(
                "{name}: file {:016x}, fingerprint {:016x}\n",
                fnv(&text),
                fnv(&s.fingerprint_text())
            ));
        }
        // The printed file reads back as the same set-up.
        let again = System::parse(&text, &builtin_robot).unwrap();
        assert_eq!(again.to_toml(), text, "{name}");
        assert_eq!(again.param_block(), s.param_block(), "{name}");
    }
    pinned("fingerprints.txt", &prints);
}

#[test]
fn bad_files_are_refused_with_the_pinned_messages() {
    let mut out = String::new();
    for (name, text) in BAD {
        let e = match System::parse(text, &builtin_robot) {
            Ok(_) => panic!("{name}: accepted"),
            Err(e) => e.to_string(),
        };
        assert!(
            e.len() < 600,
            "{name}: a long message ({} bytes): {e}",
            e.len()
        );
        out.push_str(&format!("{name}\n    {e}\n"));
    }
    pinned("errors.txt", &out);
}
