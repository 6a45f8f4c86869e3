//! Where a recording's file goes and how it is opened, for CSV, MCAP and replay alike: apart
//! from `recording`, which picks the format, so the MCAP writer need not import it.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// Opens a new recording file: owner-only, never over an existing file or link. (CSV recordings
/// go through [`crate::rotate::RotatingWriter`], which opens its files the same way.)
pub fn open(path: &Path) -> std::io::Result<std::io::BufWriter<std::fs::File>> {
    Ok(std::io::BufWriter::new(rt::files::create_new(path)?))
}

/// Resolves a recording name (empty: `recording-<unix seconds>.<default_ext>`) inside `out_dir` and creates
/// its directories.
pub fn resolve(out_dir: &Path, name: &str, default_ext: &str) -> Result<PathBuf, String> {
    let name = if name.trim().is_empty() {
        let secs = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0);
        format!("recording-{secs}.{default_ext}")
    } else {
        name.trim().to_string()
    };
    let path = crate::requests::recording_path(out_dir, &name)?;
    if let Some(dir) = path.parent() {
        rt::files::create_dir_all(dir)
            .map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    Ok(path)
}
