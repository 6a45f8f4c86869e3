//! Latency statistics shared by every subcommand: one HdrHistogram per series, percentiles in a
//! fixed order, the percentile curves the plots draw, the side-by-side ratios and target checks,
//! and the markdown table docs/performance.md quotes.
//!
//! Ratios matter more than absolute numbers here: on a shared VM every absolute time moves with
//! the neighbours' load, but two series measured interleaved in the same run see the same load,
//! so their ratio is what a reader can compare between machines.

use anyhow::{bail, Context, Result};
use hdrhistogram::Histogram;

/// Percentiles reported everywhere, in this order.
pub const PERCENTILES: [f64; 4] = [50.0, 90.0, 99.0, 99.9];

/// A histogram of nanoseconds, 1 ns to 10 s, 3 significant digits (the same bounds as the
/// daemon's, `rt::hist::new_ns`, so files from both compare directly).
pub fn histogram() -> Histogram<u64> {
    rt::hist::new_ns()
}

/// p50, p90, p99, p99.9 and max of a histogram, in ns.
pub fn summary(h: &Histogram<u64>) -> [u64; 5] {
    let mut out = [0; 5];
    for (i, p) in PERCENTILES.iter().enumerate() {
        out[i] = h.value_at_quantile(p / 100.0);
    }
    out[4] = h.max();
    out
}

/// Formats ns with a unit that keeps three significant digits.
pub fn fmt_ns(ns: f64) -> String {
    if !ns.is_finite() {
        "n/a".into()
    } else if ns < 1_000.0 {
        format!("{ns:.0} ns")
    } else if ns < 1_000_000.0 {
        format!("{:.2} µs", ns / 1e3)
    } else if ns < 1e9 {
        format!("{:.2} ms", ns / 1e6)
    } else {
        format!("{:.2} s", ns / 1e9)
    }
}

/// A latency distribution as the plots need it: (quantile, ns) points in increasing quantile,
/// the last one being the maximum at quantile 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Dist {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub count: u64,
}

impl Dist {
    /// The percentile curve of a histogram, five points per halving of the remaining tail, as
    /// HdrHistogram's own percentile output does.
    pub fn of_histogram(label: &str, h: &Histogram<u64>) -> Self {
        let points = if h.is_empty() {
            Vec::new()
        } else {
            h.iter_quantiles(5)
                .map(|v| (v.quantile_iterated_to(), v.value_iterated_to() as f64))
                .collect()
        };
        Self {
            label: label.into(),
            points,
            count: h.len(),
        }
    }

    /// Reads the `.hgrm` percentile text that `rt::hist::write_hgrm` (so the daemon and the
    /// plant) writes: rows of `Value(µs) Percentile TotalCount [1/(1-Percentile)]`.
    pub fn from_hgrm(label: &str, text: &str) -> Result<Self> {
        let mut points = Vec::new();
        let mut count = 0;
        for line in text.lines() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with("Value") {
                continue;
            }
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() < 3 {
                bail!("malformed .hgrm row {line:?}");
            }
            let value_us: f64 = f[0]
                .parse()
                .with_context(|| format!("bad value in .hgrm row {line:?}"))?;
            let q: f64 = f[1]
                .parse()
                .with_context(|| format!("bad percentile in .hgrm row {line:?}"))?;
            count = f[2]
                .parse()
                .with_context(|| format!("bad count in .hgrm row {line:?}"))?;
            if !(0.0..=1.0).contains(&q) {
                bail!("percentile {q} out of 0..=1 in .hgrm row {line:?}");
            }
            points.push((q, value_us * 1e3));
        }
        Ok(Self {
            label: label.into(),
            points,
            count,
        })
    }

    /// The value at quantile `q` (the first point at or above it), in ns; NaN if empty.
    #[cfg(test)]
    pub fn at(&self, q: f64) -> f64 {
        self.points
            .iter()
            .find(|p| p.0 >= q)
            .or(self.points.last())
            .map_or(f64::NAN, |p| p.1)
    }
}

/// `a / b`, NaN when either side is missing or zero (an empty series is never "faster").
pub fn ratio(a: f64, b: f64) -> f64 {
    if a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0 {
        a / b
    } else {
        f64::NAN
    }
}

/// Formats a ratio as `4.2×`.
pub fn fmt_ratio(r: f64) -> String {
    if r.is_finite() {
        if r < 10.0 {
            format!("{r:.2}×")
        } else {
            format!("{r:.1}×")
        }
    } else {
        "n/a".into()
    }
}

/// Which side of the limit a target wants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bound {
    AtMost(f64),
    AtLeast(f64),
}

/// A target of the issue, with the value measured in this run.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    pub what: String,
    pub value: f64,
    pub bound: Bound,
    /// The unit of `value` and the bound: `None` for a ratio (printed `2.50×`).
    pub unit: Option<&'static str>,
}

impl Target {
    pub fn new(what: impl Into<String>, value: f64, bound: Bound) -> Self {
        Self {
            what: what.into(),
            value,
            bound,
            unit: None,
        }
    }

    /// The same target for an absolute quantity in `unit` (`"µs"`, `"%"`), not a ratio.
    pub fn in_unit(self, unit: &'static str) -> Self {
        Self {
            unit: Some(unit),
            ..self
        }
    }

    fn show(&self, v: f64) -> String {
        match self.unit {
            None => fmt_ratio(v),
            Some(_) if !v.is_finite() => "n/a".into(),
            Some(u) if v < 10.0 => format!("{v:.2} {u}"),
            Some(u) => format!("{v:.1} {u}"),
        }
    }

    /// Met only with a finite measurement on the right side of the limit.
    pub fn met(&self) -> bool {
        self.value.is_finite()
            && match self.bound {
                Bound::AtMost(l) => self.value <= l,
                Bound::AtLeast(l) => self.value >= l,
            }
    }

    pub fn line(&self) -> String {
        let (op, l) = match self.bound {
            Bound::AtMost(l) => ("≤", l),
            Bound::AtLeast(l) => ("≥", l),
        };
        format!(
            "- {}: {} (target {op} {}): **{}**",
            self.what,
            self.show(self.value),
            self.show(l),
            if self.met() { "met" } else { "MISSED" }
        )
    }
}

/// A markdown table.
pub struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    pub fn new(header: &[&str]) -> Self {
        Self {
            header: header.iter().map(|s| s.to_string()).collect(),
            rows: Vec::new(),
        }
    }
    pub fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }
    pub fn render(&self) -> String {
        let mut s = format!(
            "| {} |\n|{}\n",
            self.header.join(" | "),
            "---|".repeat(self.header.len())
        );
        for r in &self.rows {
            s.push_str(&format!("| {} |\n", r.join(" | ")));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_right_on_known_data() {
        let mut h = histogram();
        for v in 1..=10_000u64 {
            h.record(v * 100).unwrap();
        }
        let s = summary(&h);
        // 3 significant digits: within 0.1 %.
        for (got, want) in s
            .iter()
            .zip([500_000u64, 900_000, 990_000, 999_000, 1_000_000])
        {
            assert!(
                (*got as f64 - want as f64).abs() <= want as f64 * 1e-3,
                "{got} vs {want}"
            );
        }
    }

    #[test]
    fn distribution_curve_matches_the_histogram() {
        let mut h = histogram();
        for v in 1..=100_000u64 {
            h.record(v * 10).unwrap();
        }
        let d = Dist::of_histogram("x", &h);
        assert_eq!(d.count, 100_000);
        assert!(d
            .points
            .windows(2)
            .all(|w| w[0].0 <= w[1].0 && w[0].1 <= w[1].1));
        assert_eq!(d.points.last().unwrap().0, 1.0);
        for q in [0.5, 0.9, 0.99, 0.999] {
            let want = q * 1e6;
            assert!(
                (d.at(q) - want).abs() <= want * 2e-3,
                "q {q}: {} vs {want}",
                d.at(q)
            );
        }
        assert!(Dist::of_histogram("empty", &histogram()).at(0.5).is_nan());
    }

    #[test]
    fn hgrm_files_read_back() {
        // What the daemon and plant write, through the same writer.
        let mut h = histogram();
        for v in 1..=1000u64 {
            h.record(v * 1000).unwrap();
        }
        let mut text = Vec::new();
        rt::hist::write_hgrm(&h, &mut text).unwrap();
        let d = Dist::from_hgrm("rt", &String::from_utf8(text).unwrap()).unwrap();
        assert_eq!(d.count, 1000);
        // The file has rows at HdrHistogram's iteration points, not at every percentile: the
        // first row at or above p is within half a percent of the true value here.
        assert!((d.at(0.5) - 500_000.0).abs() < 2_500.0, "{}", d.at(0.5));
        assert!((d.at(0.99) - 990_000.0).abs() < 5_000.0, "{}", d.at(0.99));
        assert!((d.points.last().unwrap().1 - 1_000_000.0).abs() < 1_000.0);
        assert!(Dist::from_hgrm("bad", "       1.000 1.5 3\n").is_err());
        assert!(Dist::from_hgrm("bad", "  abc 0.5 3\n").is_err());
    }

    #[test]
    fn ratios_and_targets() {
        assert_eq!(ratio(600.0, 100.0), 6.0);
        assert!(ratio(1.0, 0.0).is_nan());
        assert!(ratio(f64::NAN, 1.0).is_nan());
        assert!(Target::new("a", 6.0, Bound::AtMost(6.0)).met());
        assert!(!Target::new("a", 6.01, Bound::AtMost(6.0)).met());
        assert!(Target::new("b", 5.0, Bound::AtLeast(5.0)).met());
        assert!(!Target::new("b", 4.9, Bound::AtLeast(5.0)).met());
        // A missing measurement never meets a target, whichever its direction.
        assert!(!Target::new("c", f64::NAN, Bound::AtMost(6.0)).met());
        assert!(!Target::new("c", f64::NAN, Bound::AtLeast(0.0)).met());
        let l = Target::new("iceoryx2 p50 / floor p50", 7.5, Bound::AtMost(6.0)).line();
        assert!(
            l.contains("7.50×") && l.contains("≤ 6.00×") && l.contains("MISSED"),
            "{l}"
        );
        let l = Target::new("p99", 35.9, Bound::AtMost(10.0))
            .in_unit("µs")
            .line();
        assert!(l.contains("35.9 µs (target ≤ 10.0 µs)"), "{l}");
    }

    #[test]
    fn table_renders_markdown() {
        let mut t = Table::new(&["a", "b"]);
        t.row(vec!["1".into(), "2".into()]);
        assert_eq!(t.render(), "| a | b |\n|---|---|\n| 1 | 2 |\n");
        assert_eq!(fmt_ns(950.0), "950 ns");
        assert_eq!(fmt_ns(1500.0), "1.50 µs");
        assert_eq!(fmt_ns(f64::NAN), "n/a");
    }
}
