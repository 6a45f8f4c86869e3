//! `chaosctl export RECORDING.mcap`: what a recording holds (channels, messages, time span); with
//! `--csv` its per-tick rows in the columns of a `.csv` recording; with `--ros2 OUT` the
//! recording as a ROS 2 bag ([`daemon::ros2_bag`]).

use anyhow::{bail, Context, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// An MCAP recording (`chaosctl record start`).
    pub recording: PathBuf,
    /// Write the rows as CSV (the columns of a `.csv` recording).
    #[arg(long)]
    pub csv: bool,
    /// Where the CSV goes (default: the recording's name with `.csv`); never over a file.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Write the recording as a ROS 2 bag (an MCAP file with the `ros2` profile, every channel a
    /// standard ROS 2 message in CDR) to this file, which must not exist yet.
    #[arg(long, value_name = "OUT", conflicts_with_all = ["csv", "out"])]
    pub ros2: Option<PathBuf>,
}

pub fn run(a: ExportArgs) -> Result<()> {
    let file = daemon::mcap_read::read(&a.recording).map_err(anyhow::Error::msg)?;
    if let Some(out) = &a.ros2 {
        return ros2(&file, out);
    }
    if !a.csv {
        if a.out.is_some() {
            bail!("--out needs a format: add --csv");
        }
        let span = |t: &[daemon::mcap_read::Message]| {
            let (first, last) = (t.first().map(|m| m.log_time), t.last().map(|m| m.log_time));
            first.zip(last).map_or(0.0, |(f, l)| (l - f) as f64 * 1e-9)
        };
        println!("{}", a.recording.display());
        if let Some(arm) = file.metadata.get("arm") {
            println!("  arm      {arm}");
        }
        for (topic, msgs) in &file.topics {
            println!(
                "  {topic:<20} {:>8} messages over {:.3} s",
                msgs.len(),
                span(msgs)
            );
        }
        return Ok(());
    }
    let out = a.out.unwrap_or_else(|| a.recording.with_extension("csv"));
    let f = create_new(&out)?;
    let mut w = std::io::BufWriter::new(f);
    let rows = file.to_csv(&mut w).map_err(anyhow::Error::msg)?;
    std::io::Write::flush(&mut w).with_context(|| format!("cannot write {}", out.display()))?;
    println!("{rows} rows → {}", out.display());
    Ok(())
}

fn create_new(out: &std::path::Path) -> Result<std::fs::File> {
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(out)
        .with_context(|| format!("cannot create {} (it must not exist yet)", out.display()))
}

fn ros2(file: &daemon::mcap_read::McapFile, out: &std::path::Path) -> Result<()> {
    let f = create_new(out)?;
    let counts = match daemon::ros2_bag::write(file, std::io::BufWriter::new(f)) {
        Ok(c) => c,
        Err(e) => {
            let _ = std::fs::remove_file(out);
            bail!("cannot write {}: {e}", out.display());
        }
    };
    println!("{} (ROS 2 bag: MCAP, profile ros2, CDR)", out.display());
    for (topic, n) in counts {
        println!("  {topic:<24} {n:>8} messages");
    }
    Ok(())
}
