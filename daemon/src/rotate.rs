//! A recording that cannot fill the disk: a writer that starts a new file at a size limit and
//! keeps only the newest few.
//!
//! At 1 kHz a recording grows by about 0.86 GB an hour. [`RotatingWriter`] writes whole lines:
//! before a line would take the current file past `max_bytes`, it closes the file and starts the
//! next one, `rec.csv` → `rec.1.csv` → `rec.2.csv` …, each beginning with the same header so that
//! every file reads on its own. When more than `keep` old files exist, the oldest is deleted. A
//! file therefore never exceeds `max_bytes` (unless the header and one line alone do), and the
//! recording never takes more than `(keep + 1) · max_bytes`.
//!
//! Every file is created with `rt::files::create_new`: owner-only (0600), and never through an
//! existing file or symbolic link, as the first one is.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// Where a recording may grow to: `max_bytes` per file (None: one file without limit), and how
/// many full files to keep besides the one being written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limit {
    pub max_bytes: Option<u64>,
    pub keep: usize,
}

/// Segment `k` of the recording at `path`: `path` itself for 0, else `<stem>.<k>.<ext>`.
pub fn segment_path(path: &Path, k: u64) -> PathBuf {
    if k == 0 {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .map_or_else(Default::default, |s| s.to_string_lossy());
    let name = match path.extension() {
        Some(ext) => format!("{stem}.{k}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{k}"),
    };
    path.with_file_name(name)
}

/// With segment `current` just started, deletes the one that is now `keep + 1` segments old
/// (old files are segments 0..current; the newest `keep` of them stay).
pub fn remove_old(path: &Path, current: u64, keep: usize) -> io::Result<()> {
    if let Some(old) = current.checked_sub(keep as u64 + 1) {
        let gone = segment_path(path, old);
        match std::fs::remove_file(&gone) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => {
                return Err(io::Error::new(
                    e.kind(),
                    format!("cannot remove {}: {e}", gone.display()),
                ))
            }
            _ => {}
        }
    }
    Ok(())
}

/// A line-oriented writer that rotates at [`Limit::max_bytes`]. See the module docs.
pub struct RotatingWriter {
    path: PathBuf,
    header: Vec<u8>,
    limit: Limit,
    file: BufWriter<File>,
    /// Bytes in the current file, the header included.
    written: u64,
    /// The line being assembled (a row arrives in several `write` calls).
    line: Vec<u8>,
    /// Index of the current file.
    segment: u64,
}

impl RotatingWriter {
    /// Creates `path` (which must not exist) and writes `header` into it.
    pub fn create(path: &Path, header: &[u8], limit: Limit) -> io::Result<Self> {
        let mut w = Self {
            path: path.to_path_buf(),
            header: header.to_vec(),
            limit,
            file: BufWriter::new(rt::files::create_new(path)?),
            written: 0,
            line: Vec::with_capacity(1024),
            segment: 0,
        };
        w.file.write_all(header)?;
        w.written = header.len() as u64;
        Ok(w)
    }

    /// The file being written now.
    pub fn current_path(&self) -> PathBuf {
        segment_path(&self.path, self.segment)
    }

    /// How many times the recording moved on to a new file.
    pub fn rotations(&self) -> u64 {
        self.segment
    }

    fn rotate(&mut self) -> io::Result<()> {
        self.file.flush()?;
        let next = segment_path(&self.path, self.segment + 1);
        self.file = BufWriter::new(rt::files::create_new(&next).map_err(|e| {
            io::Error::new(e.kind(), format!("cannot start {}: {e}", next.display()))
        })?);
        self.segment += 1;
        self.file.write_all(&self.header)?;
        self.written = self.header.len() as u64;
        remove_old(&self.path, self.segment, self.limit.keep)
    }

    fn commit_line(&mut self) -> io::Result<()> {
        let len = self.line.len() as u64;
        let full = self.limit.max_bytes.is_some_and(|m| self.written + len > m);
        if full && self.written > self.header.len() as u64 {
            self.rotate()?;
        }
        self.file.write_all(&self.line)?;
        self.written += len;
        self.line.clear();
        Ok(())
    }
}

impl Write for RotatingWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut rest = buf;
        while let Some(i) = rest.iter().position(|&b| b == b'\n') {
            self.line.extend_from_slice(&rest[..=i]);
            self.commit_line()?;
            rest = &rest[i + 1..];
        }
        self.line.extend_from_slice(rest);
        Ok(buf.len())
    }

    /// Writes out a partial line too (only ever at the end of a recording).
    fn flush(&mut self) -> io::Result<()> {
        if !self.line.is_empty() {
            self.commit_line()?;
        }
        self.file.flush()
    }
}

impl Drop for RotatingWriter {
    fn drop(&mut self) {
        let _ = self.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("chaosd-rotate-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn segments_are_named_next_to_the_first_file() {
        let p = Path::new("/o/rec.csv");
        assert_eq!(segment_path(p, 0), p);
        assert_eq!(segment_path(p, 3), Path::new("/o/rec.3.csv"));
        assert_eq!(segment_path(Path::new("/o/rec"), 2), Path::new("/o/rec.2"));
    }

    #[test]
    fn files_never_exceed_the_limit_and_only_the_newest_are_kept() {
        let dir = scratch("limit");
        let path = dir.join("rec.csv");
        let limit = Limit {
            max_bytes: Some(100),
            keep: 2,
        };
        let mut w = RotatingWriter::create(&path, b"a,b\n", limit).unwrap();
        // 50 rows of 10 bytes, each written in pieces as the reporter does.
        for i in 0..50 {
            write!(w, "{i:04},").unwrap();
            writeln!(w, "xxxx").unwrap();
        }
        w.flush().unwrap();
        // 4 header bytes + 9 rows = 94 per file: 50 rows make 6 files (0..=5), 3 are kept.
        assert_eq!(w.rotations(), 5);
        assert_eq!(names(&dir), ["rec.3.csv", "rec.4.csv", "rec.5.csv"]);
        let mut rows = Vec::new();
        for f in names(&dir) {
            let p = dir.join(&f);
            let text = std::fs::read_to_string(&p).unwrap();
            assert!(text.len() <= 100, "{f} has {} bytes", text.len());
            assert!(text.starts_with("a,b\n"), "{f} lacks the header");
            assert!(text.ends_with('\n'), "{f} ends mid-row");
            assert_eq!(
                std::fs::metadata(&p).unwrap().permissions().mode() & 0o777,
                0o600
            );
            rows.extend(text.lines().skip(1).map(str::to_string));
        }
        // The kept files hold the newest rows, in order, none split.
        let first: usize = rows[0][..4].parse().unwrap();
        assert_eq!(rows.len(), 50 - first);
        for (k, r) in rows.iter().enumerate() {
            assert_eq!(r, &format!("{:04},xxxx", first + k));
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn without_a_limit_it_is_one_file_and_keep_zero_keeps_only_the_current_one() {
        let dir = scratch("nolimit");
        let mut w = RotatingWriter::create(
            &dir.join("r.csv"),
            b"h\n",
            Limit {
                max_bytes: None,
                keep: 0,
            },
        )
        .unwrap();
        for _ in 0..1000 {
            writeln!(w, "0123456789").unwrap();
        }
        drop(w);
        assert_eq!(names(&dir), ["r.csv"]);
        let mut w = RotatingWriter::create(
            &dir.join("s.csv"),
            b"h\n",
            Limit {
                max_bytes: Some(30),
                keep: 0,
            },
        )
        .unwrap();
        for _ in 0..10 {
            writeln!(w, "0123456789").unwrap();
        }
        drop(w);
        assert_eq!(names(&dir), ["r.csv", "s.4.csv"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_link_where_the_next_file_goes_is_never_followed() {
        let dir = scratch("link");
        let target = dir.join("target.txt");
        std::fs::write(&target, "mine").unwrap();
        std::os::unix::fs::symlink(&target, dir.join("r.1.csv")).unwrap();
        let mut w = RotatingWriter::create(
            &dir.join("r.csv"),
            b"h\n",
            Limit {
                max_bytes: Some(10),
                keep: 5,
            },
        )
        .unwrap();
        writeln!(w, "row1").unwrap();
        let err = writeln!(w, "row2").unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::AlreadyExists, "{err}");
        assert!(err.to_string().contains("r.1.csv"), "{err}");
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "mine");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
