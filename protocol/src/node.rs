//! How every chaosd process joins iceoryx2.
//!
//! Three defaults of iceoryx2 are wrong for us, so they are set once here: its signal handler
//! (it would take SIGINT/SIGTERM/SIGTSTP away from the processes' own shutdown handling), its
//! config-file search relative to the working directory (a stray `./config/iceoryx2.toml` must
//! not change a daemon), and its info-level logging (`IOX2_LOG_LEVEL` still overrides).
//!
//! Before joining, [`node`] checks that this user can write iceoryx2's directories (its root,
//! `/tmp/iceoryx2`, and the `nodes` and `services` directories in it). iceoryx2 creates them
//! owner-only, so after another user ran an iceoryx2 program they are that user's, and iceoryx2
//! itself only says `InternalError`, or a daemon waits for a plant it can never see. The check
//! names the directory, its owner and what to do instead ([`check_dirs`]).

use iceoryx2::node::Node;
use iceoryx2::prelude::{ipc, LogLevel, NodeBuilder, NodeName, SignalHandlingMode};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// Why a node could not be created.
#[derive(Debug, thiserror::Error)]
#[error("cannot join iceoryx2 as {name:?}: {reason}")]
pub struct NodeError {
    pub name: String,
    pub reason: String,
}

/// An inter-process node named `name` (shown by iceoryx2's node listing).
pub fn node(name: &str) -> Result<Node<ipc::Service>, NodeError> {
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Error);
    let err = |reason: String| NodeError {
        name: name.to_string(),
        reason,
    };
    let config = iceoryx2::config::Config::default();
    let g = &config.global;
    let dirs = [
        g.root_path().to_string(),
        g.node_dir().to_string(),
        g.service_dir().to_string(),
    ];
    check_dirs(dirs.iter().map(Path::new)).map_err(|e| err(e.to_string()))?;
    NodeBuilder::new()
        .name(&NodeName::new(name).map_err(|e| err(format!("{e:?}")))?)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .config(&config)
        .create::<ipc::Service>()
        .map_err(|e| err(format!("{e:?}")))
}

/// Owner, group and permission bits of a directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DirAccess {
    pub uid: u32,
    pub gid: u32,
    pub mode: u32,
}

/// Whether user `uid` in `groups` may create and remove entries in a directory (write and
/// search permission), by the permission bits of the one class that applies (owner, else group,
/// else others); root always may.
pub fn may_write(d: DirAccess, uid: u32, groups: &[u32]) -> bool {
    let has = |bits: u32| d.mode & bits == bits;
    if uid == 0 {
        true
    } else if d.uid == uid {
        has(0o300)
    } else if groups.contains(&d.gid) {
        has(0o030)
    } else {
        has(0o003)
    }
}

/// An iceoryx2 directory this user cannot use.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DirError {
    #[error(
        "iceoryx2's directory {path} belongs to {owner} (uid {owner_uid}, mode {mode:04o}) and {me} \
         cannot write to it; if no iceoryx2 program of {owner} runs any more, remove it \
         (`rm -r {path}` as {owner} or root), otherwise run chaosd as {owner}"
    )]
    NotWritable {
        path: PathBuf,
        owner: String,
        owner_uid: u32,
        me: String,
        mode: u32,
    },
    #[error("iceoryx2's directory {path} is not a directory; remove it (`rm {path}`) so iceoryx2 can create it")]
    NotADirectory { path: PathBuf },
}

/// The name of user `uid`, or "uid N" when it has none.
fn user(uid: u32) -> String {
    let mut buf = vec![0 as libc::c_char; 1024];
    // SAFETY: a zeroed passwd is a valid out-parameter.
    let mut pw: libc::passwd = unsafe { core::mem::zeroed() };
    let mut found: *mut libc::passwd = core::ptr::null_mut();
    // SAFETY: every pointer is valid for the call and `buf`'s length is passed; getpwuid_r is
    // thread-safe.
    let rc = unsafe { libc::getpwuid_r(uid, &mut pw, buf.as_mut_ptr(), buf.len(), &mut found) };
    if rc == 0 && !found.is_null() && !pw.pw_name.is_null() {
        // SAFETY: on success pw_name points to a NUL-terminated string inside `buf`.
        let name = unsafe { std::ffi::CStr::from_ptr(pw.pw_name) };
        name.to_string_lossy().into_owned()
    } else {
        format!("uid {uid}")
    }
}

fn my_groups() -> Vec<u32> {
    // SAFETY: getgroups(0, NULL) only returns the count; the second call fills at most `n` ids.
    let n = unsafe { libc::getgroups(0, core::ptr::null_mut()) };
    let mut g = vec![0 as libc::gid_t; n.max(0) as usize];
    let got = unsafe { libc::getgroups(n.max(0), g.as_mut_ptr()) };
    g.truncate(got.max(0) as usize);
    // SAFETY: getegid cannot fail.
    g.push(unsafe { libc::getegid() });
    g
}

/// Checks that this process may write each existing directory of `dirs` (those that do not exist
/// yet, iceoryx2 creates). The first one it may not is the error.
pub fn check_dirs<'a>(dirs: impl IntoIterator<Item = &'a Path>) -> Result<(), DirError> {
    // SAFETY: geteuid cannot fail.
    let uid = unsafe { libc::geteuid() };
    let groups = my_groups();
    for path in dirs {
        let Ok(meta) = std::fs::metadata(path) else {
            continue;
        };
        if !meta.is_dir() {
            return Err(DirError::NotADirectory { path: path.into() });
        }
        let d = DirAccess {
            uid: meta.uid(),
            gid: meta.gid(),
            mode: meta.mode() & 0o7777,
        };
        if !may_write(d, uid, &groups) {
            return Err(DirError::NotWritable {
                path: path.into(),
                owner: user(d.uid),
                owner_uid: d.uid,
                me: format!("{} (uid {uid})", user(uid)),
                mode: d.mode,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn only_the_class_that_applies_counts() {
        let d = |uid, gid, mode| DirAccess { uid, gid, mode };
        // iceoryx2's own layout: 0750, owned by whoever came first.
        assert!(may_write(d(1000, 1000, 0o750), 1000, &[1000]));
        assert!(!may_write(d(1001, 1001, 0o750), 1000, &[1000]));
        assert!(
            !may_write(d(1001, 1000, 0o750), 1000, &[1000]),
            "group may only read"
        );
        assert!(may_write(d(1001, 1000, 0o770), 1000, &[1000]));
        assert!(may_write(d(1001, 1001, 0o1777), 1000, &[1000]), "like /tmp");
        assert!(!may_write(d(1000, 1000, 0o555), 1000, &[1000]));
        assert!(
            !may_write(d(1000, 1000, 0o077), 1000, &[1000]),
            "the owner's bits rule"
        );
        assert!(may_write(d(1001, 1001, 0o700), 0, &[0]), "root");
    }

    #[test]
    fn a_directory_this_user_cannot_write_is_named_with_its_owner() {
        let dir = std::env::temp_dir().join(format!("chaosd-iox-{}", std::process::id()));
        let sub = dir.join("services");
        std::fs::create_dir_all(&sub).unwrap();
        assert_eq!(check_dirs([dir.as_path(), sub.as_path()]), Ok(()));
        assert_eq!(check_dirs([dir.join("missing").as_path()]), Ok(()));
        std::fs::set_permissions(&sub, std::fs::Permissions::from_mode(0o555)).unwrap();
        // SAFETY: geteuid cannot fail.
        let root = unsafe { libc::geteuid() } == 0;
        let got = check_dirs([dir.as_path(), sub.as_path()]);
        std::fs::set_permissions(&sub, std::fs::Permissions::from_mode(0o755)).unwrap();
        if root {
            assert_eq!(got, Ok(()), "root may write anything");
        } else {
            let msg = got.unwrap_err().to_string();
            assert!(
                msg.contains(&format!("{} belongs to", sub.display())),
                "{msg}"
            );
            assert!(msg.contains("mode 0555") && msg.contains("rm -r"), "{msg}");
        }
        let file = dir.join("file");
        std::fs::write(&file, "").unwrap();
        let msg = check_dirs([file.as_path()]).unwrap_err().to_string();
        assert!(msg.contains("is not a directory"), "{msg}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_message_says_what_to_do() {
        let e = DirError::NotWritable {
            path: "/tmp/iceoryx2".into(),
            owner: "alice".into(),
            owner_uid: 1001,
            me: "bob (uid 1000)".into(),
            mode: 0o750,
        };
        assert_eq!(
            e.to_string(),
            "iceoryx2's directory /tmp/iceoryx2 belongs to alice (uid 1001, mode 0750) and bob (uid 1000) \
             cannot write to it; if no iceoryx2 program of alice runs any more, remove it \
             (`rm -r /tmp/iceoryx2` as alice or root), otherwise run chaosd as alice"
        );
        assert_eq!(user(0), "root");
    }
}
