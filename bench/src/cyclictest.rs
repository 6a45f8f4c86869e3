//! Running cyclictest (rt-tests), the standard wake-up latency tool, and reading its histogram.
//!
//! `cyclictest -q -h LIMIT` prints, at exit, one row per microsecond bucket (`000012 000876`:
//! 876 wake-ups were 12 µs late), then `# Total:`, `# Min/Avg/Max Latencies:` and
//! `# Histogram Overflows:` (wake-ups later than LIMIT). That text is the same in every rt-tests
//! release, unlike `--json`, which old ones lack.
//!
//! cyclictest truncates to whole microseconds, so bucket b holds latencies in [b, b+1) µs. It is
//! recorded here as b µs, the lower bound: every cyclictest percentile we report is at most its
//! true value, which can only make cyclictest look better than it is next to our
//! nanosecond-resolution numbers. Overflows are recorded at LIMIT (again a lower bound), except
//! one at the reported maximum, so the maximum is exact.

use anyhow::{anyhow, bail, Context, Result};
use hdrhistogram::Histogram;
use std::path::PathBuf;

/// cyclictest on the PATH, if installed.
pub fn find() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join("cyclictest"))
        .find(|p| p.is_file())
}

/// Arguments for one measurement thread on `core`, `loops` wake-ups every `period_us`, with
/// SCHED_FIFO `priority` (or SCHED_OTHER for `None`), memory locked, histogram up to `limit_us`.
///
/// By default cyclictest also "tunes the system" while it runs: it holds /dev/cpu_dma_latency at
/// 0 µs, a PM QoS request that keeps idle CPUs polling instead of halting, which shortens
/// wake-ups (on a VM, halting exits to the host). `pm_qos = false` adds `--default-system` to
/// measure without that request, as chaosd's own loops run; `jitter` shows both side by side.
pub fn args(
    core: usize,
    priority: Option<u8>,
    period_us: u64,
    loops: u64,
    limit_us: u64,
    pm_qos: bool,
) -> Vec<String> {
    let (prio, policy) = match priority {
        Some(p) => (p, "fifo"),
        None => (0, "other"),
    };
    let mut v: Vec<String> = vec![
        "-q".into(),
        "-m".into(),
        "-t".into(),
        "1".into(),
        "-a".into(),
        core.to_string(),
        "-p".into(),
        prio.to_string(),
        format!("--policy={policy}"),
        "-i".into(),
        period_us.to_string(),
        "-l".into(),
        loops.to_string(),
        "-h".into(),
        limit_us.to_string(),
    ];
    if !pm_qos {
        v.push("--default-system".into());
    }
    v
}

/// What one cyclictest run reported.
#[derive(Debug)]
pub struct Run {
    /// Wake-up lateness in ns (see the module docs for how buckets are placed).
    pub hist: Histogram<u64>,
    /// Wake-ups later than the histogram limit.
    pub overflows: u64,
}

fn header_value(line: &str, key: &str) -> Option<Result<u64>> {
    let rest = line.strip_prefix('#')?.trim_start().strip_prefix(key)?;
    let first = rest.split_whitespace().next().unwrap_or("");
    Some(
        first
            .parse::<u64>()
            .with_context(|| format!("bad number in cyclictest line {line:?}")),
    )
}

/// Parses cyclictest's `-q -h LIMIT` output (one thread).
pub fn parse(text: &str, limit_us: u64) -> Result<Run> {
    let mut hist = crate::stats::histogram();
    let (mut total, mut max, mut overflows) = (None, None, None);
    let mut rows = 0u64;
    for line in text.lines() {
        let line = line.trim();
        if line.starts_with('#') {
            if let Some(v) = header_value(line, "Total:") {
                total = Some(v?);
            } else if let Some(v) = header_value(line, "Max Latencies:") {
                max = Some(v?);
            } else if let Some(v) = header_value(line, "Histogram Overflows:") {
                overflows = Some(v?);
            }
            continue;
        }
        if !line.starts_with(|c: char| c.is_ascii_digit()) {
            continue; // a warning or other chatter
        }
        let mut f = line.split_whitespace();
        let (Some(bucket), Some(count)) = (f.next(), f.next()) else {
            bail!("malformed cyclictest histogram row {line:?}");
        };
        let bucket: u64 = bucket
            .parse()
            .with_context(|| format!("bad bucket in cyclictest row {line:?}"))?;
        let count: u64 = count
            .parse()
            .with_context(|| format!("bad count in cyclictest row {line:?}"))?;
        if count > 0 {
            hist.saturating_record_n((bucket * 1000).max(1), count);
        }
        rows += count;
    }
    let max =
        max.ok_or_else(|| anyhow!("no `# Max Latencies:` line: not a cyclictest -q -h output"))?;
    let total = total.ok_or_else(|| anyhow!("no `# Total:` line in the cyclictest output"))?;
    if rows != total {
        bail!("the cyclictest histogram rows add up to {rows}, but it reports a total of {total}");
    }
    let overflows = overflows.unwrap_or(0);
    if overflows > 0 {
        if max >= limit_us {
            hist.saturating_record_n(limit_us * 1000, overflows - 1);
            hist.saturating_record(max * 1000);
        } else {
            hist.saturating_record_n((max * 1000).max(1), overflows);
        }
    }
    Ok(Run { hist, overflows })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::summary;

    /// The shape of real `cyclictest -q -m -t 1 -h 400` output (rt-tests 2.4, this VM), trimmed.
    const SAMPLE: &str = "\
# /dev/cpu_dma_latency set to 0us
# Histogram
000000 000000
000007 000003
000008 000087
000009 000138
000010 000064
000011 000100
000012 000963
000013 000466
000014 000047
000015 000016
000016 000001
000029 000021
000030 000031
000031 000005
000032 000005
000033 000002
000034 000001
000042 000001
000044 000001
000045 000001
000048 000001
000180 000001
000187 000001
000350 000001
000399 000000
# Total: 000001957
# Min Latencies: 00007
# Avg Latencies: 00013
# Max Latencies: 00350
# Histogram Overflows: 00000
# Histogram Overflow at cycle number:
# Thread 0:
";

    #[test]
    fn parses_the_histogram() {
        let r = parse(SAMPLE, 400).unwrap();
        assert_eq!(r.hist.len(), 1957);
        assert_eq!(r.overflows, 0);
        assert!(
            (r.hist.min() as i64 - 7_000).abs() <= 7,
            "min {}",
            r.hist.min()
        );
        let s = summary(&r.hist);
        // Cumulative counts: ≤11 µs: 392, ≤12 µs: 1355 (69 %), ≤13 µs: 1821 (93 %),
        // ≤30 µs: 1937 (98.98 %), ≤31 µs: 1942 (99.2 %); max 350 µs.
        for (got, want, what) in [
            (s[0], 12_000, "p50"),
            (s[1], 13_000, "p90"),
            (s[2], 31_000, "p99"),
            (s[4], 350_000, "max"),
        ] {
            assert!(
                (got as i64 - want).abs() <= want / 500,
                "{what}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn overflows_are_lower_bounds_with_an_exact_max() {
        let text = "000005 000010\n# Total: 000000010\n# Min Latencies: 00005\n# Max Latencies: 02500\n# Histogram Overflows: 00003\n";
        let r = parse(text, 1000).unwrap();
        assert_eq!((r.hist.len(), r.overflows), (13, 3));
        assert_eq!(r.hist.count_at(1_000_000), 2);
        assert!((r.hist.max() as i64 - 2_500_000).abs() <= 2_500);
        // A mixed stdout/stderr log with warnings still parses.
        let noisy = format!("WARN: stat /dev/cpu_dma_latency failed\n{text}");
        assert_eq!(parse(&noisy, 1000).unwrap().hist.len(), 13);
    }

    #[test]
    fn truncated_or_foreign_output_is_refused() {
        let cut = SAMPLE.lines().take(10).collect::<Vec<_>>().join("\n");
        assert!(parse(&cut, 400)
            .unwrap_err()
            .to_string()
            .contains("Max Latencies"));
        let wrong_total = SAMPLE.replace("# Total: 000001957", "# Total: 000002000");
        assert!(parse(&wrong_total, 400)
            .unwrap_err()
            .to_string()
            .contains("add up to 1957"));
        assert!(parse("000012 abc\n# Max Latencies: 00001\n# Total: 0\n", 400).is_err());
        assert_eq!(
            args(1, Some(50), 200, 1000, 5000, true).join(" "),
            "-q -m -t 1 -a 1 -p 50 --policy=fifo -i 200 -l 1000 -h 5000"
        );
        let other = args(1, None, 1000, 10, 5000, false).join(" ");
        assert!(other.contains("-p 0 --policy=other"), "{other}");
        assert!(other.ends_with("--default-system"), "{other}");
    }
}
