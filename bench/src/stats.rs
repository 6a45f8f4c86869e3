//! Latency statistics shared by every subcommand: one HdrHistogram per series, percentiles in a
//! fixed order, and the markdown table the README quotes.

use hdrhistogram::Histogram;

/// Percentiles reported everywhere, in this order.
pub const PERCENTILES: [f64; 4] = [50.0, 90.0, 99.0, 99.9];

/// A histogram of nanoseconds, 1 ns to 10 s, 3 significant digits.
pub fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("static bounds are valid")
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
    if ns < 1_000.0 {
        format!("{ns:.0} ns")
    } else if ns < 1_000_000.0 {
        format!("{:.2} µs", ns / 1e3)
    } else if ns < 1e9 {
        format!("{:.2} ms", ns / 1e6)
    } else {
        format!("{:.2} s", ns / 1e9)
    }
}

/// A markdown table.
pub struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    pub fn new(header: &[&str]) -> Self {
        Self { header: header.iter().map(|s| s.to_string()).collect(), rows: Vec::new() }
    }
    pub fn row(&mut self, cells: Vec<String>) {
        self.rows.push(cells);
    }
    pub fn render(&self) -> String {
        let mut s = format!("| {} |\n|{}\n", self.header.join(" | "), "---|".repeat(self.header.len()));
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
        for (got, want) in s.iter().zip([500_000u64, 900_000, 990_000, 999_000, 1_000_000]) {
            assert!((*got as f64 - want as f64).abs() <= want as f64 * 1e-3, "{got} vs {want}");
        }
    }

    #[test]
    fn table_renders_markdown() {
        let mut t = Table::new(&["a", "b"]);
        t.row(vec!["1".into(), "2".into()]);
        assert_eq!(t.render(), "| a | b |\n|---|---|\n| 1 | 2 |\n");
        assert_eq!(fmt_ns(950.0), "950 ns");
        assert_eq!(fmt_ns(1500.0), "1.50 µs");
    }
}
