//! What every subcommand leaves behind: a markdown report, `.hgrm` files and plots, in one
//! directory per subcommand, headed by the date and a description of the machine (a number
//! without its machine is meaningless); and its tables by name, for `--book` (`crate::book`).

use crate::book::table::{tables_in, Table};
use anyhow::{bail, Context, Result};
use hdrhistogram::Histogram;
use std::path::{Path, PathBuf};

/// A subcommand's output directory and the report text it builds up.
pub struct Report {
    pub dir: PathBuf,
    name: String,
    text: String,
    pub files: Vec<PathBuf>,
    tables: Vec<Table>,
    detail: Option<String>,
}

/// What a finished subcommand returns: its report text, and its tables for the book.
pub struct Output {
    pub text: String,
    pub tables: Vec<Table>,
}

impl Report {
    /// Creates `<out>/<name>/`.
    pub fn new(out: &Path, name: &str) -> Result<Self> {
        let dir = out.join(name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create output directory {}", dir.display()))?;
        Ok(Self {
            dir,
            name: name.into(),
            text: String::new(),
            files: Vec::new(),
            tables: Vec::new(),
            detail: None,
        })
    }

    /// Appends markdown (a table, a paragraph) to the report.
    pub fn push(&mut self, markdown: &str) {
        self.text.push_str(markdown);
        if !markdown.ends_with('\n') {
            self.text.push('\n');
        }
    }

    /// What the book's run line says about how much was measured ("40 rounds × 5000 round
    /// trips per transport"), for the tables named after this.
    pub fn run_detail(&mut self, detail: String) {
        self.detail = Some(detail);
    }

    /// Appends a markdown table, and keeps it under `name` for the book.
    pub fn table(&mut self, name: &'static str, markdown: &str) -> Result<()> {
        self.push_tables(markdown, &[name])
    }

    /// Appends markdown holding one table per name, in order, and keeps each for the book
    /// under its name. Fewer or more tables than names is a bug of the part.
    pub fn push_tables(&mut self, markdown: &str, names: &[&'static str]) -> Result<()> {
        let found = tables_in(markdown);
        if found.len() != names.len() {
            bail!(
                "{}: {} table(s) where the book expects {} ({}): a bug in chaosd-bench",
                self.name,
                found.len(),
                names.len(),
                names.join(", ")
            );
        }
        self.push(markdown);
        for (name, markdown) in names.iter().zip(found) {
            self.tables.push(Table {
                name,
                date: now_utc(),
                detail: self.detail.clone(),
                markdown,
            });
        }
        Ok(())
    }

    /// A path inside the directory.
    pub fn path(&self, file: &str) -> PathBuf {
        self.dir.join(file)
    }

    /// Writes `<slug>.hgrm` (HdrHistogram percentile text, values in µs).
    pub fn hgrm(&mut self, slug: &str, h: &Histogram<u64>) -> Result<()> {
        let p = self.path(&format!("{slug}.hgrm"));
        rt::hist::save_hgrm(h, &p).with_context(|| format!("cannot write {}", p.display()))?;
        self.files.push(p);
        Ok(())
    }

    /// Writes the plot `<name>.png` / `<name>.svg`.
    pub fn plot(&mut self, title: &str, panels: &[crate::plot::Panel]) -> Result<()> {
        let files = crate::plot::save(title, panels, &self.path(&self.name))?;
        self.files.extend(files);
        Ok(())
    }

    /// Writes `<name>.md` and returns the report text, with the list of files at the end, and
    /// the tables.
    pub fn finish(mut self) -> Result<Output> {
        let md = self.path(&format!("{}.md", self.name));
        self.files.push(md.clone());
        let mut files: Vec<String> = self.files.iter().map(|f| f.display().to_string()).collect();
        files.sort();
        self.text
            .push_str(&format!("\nFiles: {}\n", files.join(", ")));
        std::fs::write(&md, &self.text)
            .with_context(|| format!("cannot write {}", md.display()))?;
        Ok(Output {
            text: self.text,
            tables: self.tables,
        })
    }
}

/// A file-name-safe version of a label.
pub fn slug(label: &str) -> String {
    let mut s: String = label
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect();
    while s.contains("--") {
        s = s.replace("--", "-");
    }
    s.trim_matches('-').to_string()
}

/// Today's date and time in UTC, `YYYY-MM-DD HH:MM UTC`.
pub fn now_utc() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60
    )
}

/// Days since 1970-01-01 → (year, month, day), proleptic Gregorian (H. Hinnant's algorithm).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// "2 vCPU (AMD EPYC), Linux 6.1.0, Debian GNU/Linux 12 (bookworm)", from /proc and /etc.
pub fn machine() -> String {
    // Online CPUs of the machine (available_parallelism would give the calling thread's
    // affinity, which is one core in a pinned benchmark thread).
    // SAFETY: sysconf has no preconditions.
    let cpus = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_ONLN) };
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .map_or_else(|_| "unknown".into(), |s| s.trim().to_string());
    let os = std::fs::read_to_string("/etc/os-release")
        .ok()
        .and_then(|t| {
            t.lines().find_map(|l| {
                l.strip_prefix("PRETTY_NAME=")
                    .map(|v| v.trim_matches('"').to_string())
            })
        })
        .unwrap_or_else(|| "unknown OS".into());
    let virt = if std::fs::read_to_string("/proc/cpuinfo").is_ok_and(|t| t.contains(" hypervisor"))
    {
        " vCPU"
    } else {
        " CPU"
    };
    format!("{cpus}{virt} ({model}), Linux {kernel}, {os}")
}

/// The first lines of every report.
pub fn header(title: &str, command: &str) -> String {
    format!(
        "## {title}\n\n{} on {}. Reproduce: `{command}`.\n\n",
        now_utc(),
        machine()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_and_slugs() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(19_723), (2024, 1, 1));
        assert_eq!(civil_from_days(20_513), (2026, 3, 1)); // after a non-leap February
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(
            slug("iceoryx2 pub-sub, busy poll"),
            "iceoryx2-pub-sub-busy-poll"
        );
        assert_eq!(slug("UDP (127.0.0.1)"), "udp-127-0-0-1");
        assert!(machine().contains("Linux"));
        assert!(now_utc().ends_with("UTC"));
    }
}
