//! Latency histograms and the two file formats tools read: the HdrHistogram V2 interval log
//! (`.hlog`, for HdrHistogram's plotters and `hdr-plot`) and the percentile-distribution text
//! (`.hgrm`, what `HistogramLogProcessor` prints and the online plotter accepts).
//!
//! Bounds are fixed at creation and values are recorded with `saturating_record`, so recording
//! never allocates and never fails in a loop.

use hdrhistogram::serialization::interval_log::{IntervalLogWriterBuilder, Tag};
use hdrhistogram::serialization::V2DeflateSerializer;
use hdrhistogram::Histogram;
use serde::Serialize;
use std::io::Write;
use std::path::Path;
use std::time::{Duration, SystemTime};

/// Highest recordable value: 10 s in ns. Anything above saturates (and shows as the max).
pub const MAX_NS: u64 = 10_000_000_000;

/// A histogram of nanoseconds, 1 ns to 10 s, 3 significant digits (fixed size, ~200 KB).
pub fn new_ns() -> Histogram<u64> {
    Histogram::new_with_bounds(1, MAX_NS, 3).expect("static bounds are valid")
}

/// Percentiles in µs, the numbers every report shows.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct Percentiles {
    pub count: u64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub mean_us: f64,
}

impl Percentiles {
    pub fn of(h: &Histogram<u64>) -> Self {
        if h.is_empty() {
            return Self::default();
        }
        let us = |v: u64| v as f64 / 1000.0;
        Self {
            count: h.len(),
            p50_us: us(h.value_at_quantile(0.50)),
            p90_us: us(h.value_at_quantile(0.90)),
            p99_us: us(h.value_at_quantile(0.99)),
            p999_us: us(h.value_at_quantile(0.999)),
            max_us: us(h.max()),
            mean_us: h.mean() / 1000.0,
        }
    }

    pub fn one_line(&self) -> String {
        format!(
            "p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs (n = {})",
            self.p50_us, self.p99_us, self.p999_us, self.max_us, self.count
        )
    }
}

/// Writes the percentile distribution of a ns histogram in µs, in HdrHistogram's `.hgrm` format.
pub fn write_hgrm(h: &Histogram<u64>, out: &mut impl Write) -> std::io::Result<()> {
    const SCALE: f64 = 1000.0; // ns → µs
    writeln!(
        out,
        "{:>12} {:>14} {:>10} {:>14}\n",
        "Value", "Percentile", "TotalCount", "1/(1-Percentile)"
    )?;
    if !h.is_empty() {
        // TotalCount is cumulative: the number of values at or below this row's value.
        let mut total = 0u64;
        for v in h.iter_quantiles(5) {
            total += v.count_since_last_iteration();
            let q = v.quantile_iterated_to();
            let value = v.value_iterated_to() as f64 / SCALE;
            if q < 1.0 {
                writeln!(
                    out,
                    "{:12.3} {:2.12} {:10} {:14.2}",
                    value,
                    q,
                    total,
                    1.0 / (1.0 - q)
                )?;
            } else {
                writeln!(out, "{:12.3} {:2.12} {:10}", value, q, total)?;
            }
        }
    }
    let (mean, sd, max) = if h.is_empty() {
        (0.0, 0.0, 0.0)
    } else {
        (h.mean() / SCALE, h.stdev() / SCALE, h.max() as f64 / SCALE)
    };
    writeln!(out, "#[Mean    = {mean:12.3}, StdDeviation   = {sd:12.3}]")?;
    writeln!(
        out,
        "#[Max     = {max:12.3}, Total count    = {:12}]",
        h.len()
    )?;
    writeln!(
        out,
        "#[Buckets = {:12}, SubBuckets     = {:12}]",
        h.buckets(),
        h.distinct_values()
    )?;
    Ok(())
}

/// Writes `.hgrm` to a file.
pub fn save_hgrm(h: &Histogram<u64>, path: &Path) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(crate::files::create(path)?);
    write_hgrm(h, &mut f)?;
    f.flush()
}

/// Writes several tagged histograms as one V2 interval log (one interval each, covering the run).
pub fn save_hlog(
    entries: &[(&str, &Histogram<u64>)],
    start: SystemTime,
    duration: Duration,
    path: &Path,
) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(crate::files::create(path)?);
    let mut ser = V2DeflateSerializer::new();
    {
        let mut w = IntervalLogWriterBuilder::new()
            .add_comment("chaosd latency histograms, values in ns")
            .with_start_time(start)
            .with_base_time(start)
            .with_max_value_divisor(1000.0)
            .begin_log_with(&mut f, &mut ser)
            .map_err(std::io::Error::other)?;
        for (tag, h) in entries {
            let tag = Tag::new(tag)
                .ok_or_else(|| std::io::Error::other(format!("bad histogram tag {tag:?}")))?;
            w.write_histogram(h, Duration::ZERO, duration, Some(tag))
                .map_err(|e| std::io::Error::other(format!("{e:?}")))?;
        }
    }
    f.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use hdrhistogram::serialization::interval_log::{IntervalLogIterator, LogEntry};
    use hdrhistogram::serialization::Deserializer;

    #[test]
    fn percentiles_on_known_data() {
        let mut h = new_ns();
        for v in 1..=1000u64 {
            h.saturating_record(v * 1000); // 1 µs .. 1 ms
        }
        let p = Percentiles::of(&h);
        assert!((p.p50_us - 500.0).abs() < 1.0, "{p:?}");
        assert!((p.p99_us - 990.0).abs() < 1.0, "{p:?}");
        assert!((p.max_us - 1000.0).abs() < 1.0, "{p:?}");
        h.saturating_record(u64::MAX);
        assert!((Percentiles::of(&h).max_us - MAX_NS as f64 / 1000.0).abs() / 1e7 < 1e-2);
    }

    #[test]
    fn hgrm_and_hlog_are_readable() {
        let mut h = new_ns();
        for v in [1000u64, 2000, 3000, 100_000] {
            h.saturating_record(v);
        }
        let mut text = Vec::new();
        write_hgrm(&h, &mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains("Percentile"));
        assert!(text.contains("Total count    =            4"), "{text}");
        let last = text
            .lines()
            .rfind(|l| !l.starts_with('#') && !l.trim().is_empty())
            .unwrap();
        assert!(last.trim_start().starts_with("100.0"), "{last}");
        let total: u64 = last.split_whitespace().nth(2).unwrap().parse().unwrap();
        assert_eq!(total, 4, "the last row's TotalCount is cumulative: {last}");

        let dir = std::env::temp_dir().join(format!("rt-hist-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.hlog");
        save_hlog(
            &[("lateness", &h)],
            SystemTime::now(),
            Duration::from_secs(3),
            &path,
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut found = 0;
        for e in IntervalLogIterator::new(&bytes) {
            if let Ok(LogEntry::Interval(i)) = e {
                assert_eq!(i.tag().map(|t| t.as_str()), Some("lateness"));
                let raw = base64_decode(i.encoded_histogram());
                let back: Histogram<u64> = Deserializer::new().deserialize(&mut &raw[..]).unwrap();
                assert_eq!(back.len(), 4);
                assert_eq!(back.max(), h.max());
                found += 1;
            }
        }
        assert_eq!(found, 1);
        std::fs::remove_dir_all(&dir).ok();
    }

    fn base64_decode(s: &str) -> Vec<u8> {
        let table = |c: u8| -> u32 {
            match c {
                b'A'..=b'Z' => (c - b'A') as u32,
                b'a'..=b'z' => (c - b'a' + 26) as u32,
                b'0'..=b'9' => (c - b'0' + 52) as u32,
                b'+' => 62,
                b'/' => 63,
                _ => 0,
            }
        };
        let bytes: Vec<u8> = s.bytes().filter(|&c| c != b'=').collect();
        let mut out = Vec::new();
        for chunk in bytes.chunks(4) {
            let mut v = 0u32;
            for (i, &c) in chunk.iter().enumerate() {
                v |= table(c) << (18 - 6 * i);
            }
            let n = chunk.len() * 6 / 8;
            for i in 0..n {
                out.push((v >> (16 - 8 * i)) as u8);
            }
        }
        out
    }
}
