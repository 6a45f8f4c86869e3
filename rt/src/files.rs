//! Files the processes write are the operator's alone.
//!
//! Recordings, histograms and summaries describe the arm and its controller; on a shared machine
//! no other user needs to read them. Every file chaosd writes goes through these helpers, which
//! create directories 0700 and files 0600 whatever the umask. (A process-wide umask would do the
//! same, but it would also apply to iceoryx2's machine-global management files, which other users'
//! processes must be able to open.)

use std::fs::{DirBuilder, File, OpenOptions};
use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
use std::path::Path;

/// `mkdir -p` with mode 0700 for every directory it creates.
pub fn create_dir_all(path: &Path) -> std::io::Result<()> {
    DirBuilder::new().recursive(true).mode(0o700).create(path)
}

/// Creates (or truncates) a file with mode 0600; a file that existed with a wider mode (left
/// by an older version, or created by hand) is narrowed to 0600 too.
pub fn create(path: &Path) -> std::io::Result<File> {
    use std::os::unix::fs::PermissionsExt;
    let f = OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(path)?;
    if f.metadata()?.permissions().mode() & 0o077 != 0 {
        f.set_permissions(std::fs::Permissions::from_mode(0o600))?;
    }
    Ok(f)
}

/// Creates a new file with mode 0600; fails if anything exists at `path` (links included).
pub fn create_new(path: &Path) -> std::io::Result<File> {
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
}

/// Writes a whole file with mode 0600.
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> std::io::Result<()> {
    create(path)?.write_all(bytes.as_ref())
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn created_files_and_directories_are_owner_only() {
        let dir = std::env::temp_dir().join(format!("chaosd-files-{}", std::process::id()));
        super::create_dir_all(&dir.join("sub")).unwrap();
        super::write(&dir.join("sub/f"), b"x").unwrap();
        super::create_new(&dir.join("g")).unwrap();
        assert!(super::create_new(&dir.join("g")).is_err());
        let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&dir.join("sub")), 0o700);
        assert_eq!(mode(&dir.join("sub/f")), 0o600);
        assert_eq!(mode(&dir.join("g")), 0o600);
        // A file left world-readable is narrowed when it is written again.
        let old = dir.join("old");
        std::fs::write(&old, b"x").unwrap();
        std::fs::set_permissions(&old, std::fs::Permissions::from_mode(0o644)).unwrap();
        super::write(&old, b"y").unwrap();
        assert_eq!(mode(&old), 0o600);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
