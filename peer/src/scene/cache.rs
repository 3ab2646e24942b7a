//! Where a joiner keeps the scenes it was sent: a folder of this user's, that no other user
//! can write into or read, whose writes never follow a link, and that is cleaned.
//!
//! The default is `$XDG_CACHE_HOME/softsync/scenes` (else `$HOME/.cache/softsync/scenes`,
//! else `<temp>/softsync-scenes-<uid>`). Before a bundle is unpacked the folder is made if
//! missing and checked: a real directory (not a link), owned by this user, mode `0700`
//! (tightened if it was looser); anything else is an error, so another user who made the
//! folder first (in a shared temp dir) cannot swap its files. Every unpacked scene is a
//! folder named by its bundle's digest; the oldest go when there are more than
//! [`KEEP_SCENES`] or one is older than [`KEEP_FOR`].

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

/// Scenes kept (the most recently unpacked).
pub const KEEP_SCENES: usize = 16;
/// A scene not unpacked again for this long is removed.
pub const KEEP_FOR: Duration = Duration::from_secs(30 * 24 * 3600);

/// The wall clock: the cache's folders are dated by it (file times are the system's).
#[allow(clippy::disallowed_methods)]
pub(crate) fn wall_now() -> SystemTime {
    SystemTime::now()
}

/// This user's default scene cache (see the module's documentation).
pub fn default_scene_cache() -> PathBuf {
    let nonempty = |v: &str| {
        std::env::var_os(v)
            .filter(|s| !s.is_empty())
            .map(PathBuf::from)
    };
    if let Some(x) = nonempty("XDG_CACHE_HOME").filter(|p| p.is_absolute()) {
        return x.join("softsync").join("scenes");
    }
    if let Some(h) = nonempty("HOME").filter(|p| p.is_absolute()) {
        return h.join(".cache").join("softsync").join("scenes");
    }
    let uid = my_uid().map_or_else(|| "unknown".to_owned(), |u| u.to_string());
    std::env::temp_dir().join(format!("softsync-scenes-{uid}"))
}

/// This process's user id (the owner of `/proc/self`).
fn my_uid() -> Option<u32> {
    std::fs::metadata("/proc/self").ok().map(|m| m.uid())
}

/// Make `cache` if missing and check it is this user's private directory (tightening its
/// mode to `0700`); why not, if it cannot be.
pub fn prepare(cache: &Path) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| format!("scene cache {}: {e}", cache.display());
    if std::fs::symlink_metadata(cache).is_err() {
        std::fs::create_dir_all(cache).map_err(|e| err(&e))?;
    }
    let m = std::fs::symlink_metadata(cache).map_err(|e| err(&e))?;
    if m.file_type().is_symlink() || !m.is_dir() {
        return Err(err(&"not a directory of its own (a link or a file)"));
    }
    if let Some(uid) = my_uid() {
        if m.uid() != uid {
            return Err(err(&format_args!(
                "owned by user {}, not this user ({uid}): choose another folder",
                m.uid()
            )));
        }
    }
    if m.permissions().mode() & 0o077 != 0 {
        std::fs::set_permissions(cache, std::fs::Permissions::from_mode(0o700))
            .map_err(|e| err(&e))?;
    }
    Ok(())
}

/// Make the folders from `root` down to `dir` (inside it), refusing any that is a link.
pub(crate) fn make_dirs(root: &Path, dir: &Path) -> Result<(), String> {
    let rel = dir.strip_prefix(root).map_err(|_| {
        format!(
            "scene cache: {} is outside {}",
            dir.display(),
            root.display()
        )
    })?;
    let mut at = root.to_path_buf();
    for c in rel.components() {
        at.push(c);
        match std::fs::symlink_metadata(&at) {
            Ok(m) if m.is_dir() && !m.file_type().is_symlink() => {}
            Ok(_) => return Err(format!("scene cache {}: not a directory", at.display())),
            Err(_) => match std::fs::create_dir(&at) {
                Ok(()) => {}
                // another process of ours made it meanwhile
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    let m = std::fs::symlink_metadata(&at)
                        .map_err(|e| format!("scene cache {}: {e}", at.display()))?;
                    if !m.is_dir() || m.file_type().is_symlink() {
                        return Err(format!("scene cache {}: not a directory", at.display()));
                    }
                }
                Err(e) => return Err(format!("scene cache {}: {e}", at.display())),
            },
        }
    }
    Ok(())
}

/// A scene unpacked this recently is never removed for the count alone.
const IN_USE: Duration = Duration::from_secs(3600);

/// Remove the oldest scenes of `cache` beyond [`KEEP_SCENES`] (unpacked over an hour ago) or
/// older than [`KEEP_FOR`], never `keep`; the names removed. Folders only (a file or link there is not ours: left).
pub fn clean(cache: &Path, keep: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(cache) else {
        return Vec::new();
    };
    let now = wall_now();
    let mut scenes: Vec<(SystemTime, PathBuf)> = entries
        .flatten()
        .filter_map(|e| {
            let m = std::fs::symlink_metadata(e.path()).ok()?;
            (m.is_dir() && !m.file_type().is_symlink())
                .then(|| (m.modified().unwrap_or(SystemTime::UNIX_EPOCH), e.path()))
        })
        .filter(|(_, p)| p != keep)
        .collect();
    scenes.sort_by_key(|s| std::cmp::Reverse(s.0));
    let mut removed = Vec::new();
    for (i, (at, p)) in scenes.into_iter().enumerate() {
        let age = now.duration_since(at).unwrap_or_default();
        // `keep` is one of the KEEP_SCENES; a scene unpacked within the hour may be running
        // in another process (which serves it from these files): it stays
        let extra = i + 1 >= KEEP_SCENES && age > IN_USE;
        if (age > KEEP_FOR || extra) && std::fs::remove_dir_all(&p).is_ok() {
            removed.push(p);
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn scratch(test: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("softsync-cache-test-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn the_cache_is_made_private_and_a_link_or_file_in_its_place_is_refused() {
        let d = scratch("private");
        let c = d.join("scenes");
        prepare(&c).unwrap();
        assert_eq!(
            std::fs::metadata(&c).unwrap().permissions().mode() & 0o777,
            0o700
        );
        // a world-writable one is tightened
        std::fs::set_permissions(&c, std::fs::Permissions::from_mode(0o777)).unwrap();
        prepare(&c).unwrap();
        assert_eq!(
            std::fs::metadata(&c).unwrap().permissions().mode() & 0o777,
            0o700
        );
        // a link to somewhere else, or a file: refused
        let link = d.join("link");
        std::os::unix::fs::symlink(&c, &link).unwrap();
        assert!(prepare(&link).unwrap_err().contains("link"));
        let file = d.join("file");
        std::fs::write(&file, b"x").unwrap();
        assert!(prepare(&file).is_err());
        // a link inside, where a scene's folder goes: refused, nothing written through it
        let target = d.join("elsewhere");
        std::fs::create_dir_all(&target).unwrap();
        std::os::unix::fs::symlink(&target, c.join("abcd")).unwrap();
        let e = make_dirs(&c, &c.join("abcd").join("meshes")).unwrap_err();
        assert!(e.contains("not a directory"), "{e}");
        assert!(!target.join("meshes").exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn cleaning_keeps_the_newest_scenes_and_the_one_in_use() {
        let c = scratch("clean");
        prepare(&c).unwrap();
        let t0 = wall_now() - Duration::from_secs(7200);
        let mut dirs = Vec::new();
        for i in 0..KEEP_SCENES + 4 {
            let p = c.join(format!("scene{i:02}"));
            std::fs::create_dir(&p).unwrap();
            std::fs::write(p.join("room.ron"), b"()").unwrap();
            let f = std::fs::File::open(&p).unwrap();
            f.set_modified(t0 + Duration::from_secs(i as u64)).unwrap();
            dirs.push(p);
        }
        // one far too old
        let f = std::fs::File::open(&dirs[KEEP_SCENES + 3]).unwrap();
        f.set_modified(wall_now() - KEEP_FOR - Duration::from_secs(60))
            .unwrap();
        // a file that is not a scene folder stays
        std::fs::write(c.join("note"), b"x").unwrap();
        // one unpacked just now (another process's) stays whatever the count
        let fresh = c.join("fresh");
        std::fs::create_dir(&fresh).unwrap();
        let keep = dirs[0].clone();
        let removed = clean(&c, &keep);
        assert!(keep.exists(), "the scene in use stays");
        assert!(c.join("note").exists());
        assert!(fresh.exists());
        let left = std::fs::read_dir(&c).unwrap().count() - 2;
        assert_eq!(left, KEEP_SCENES - 1, "removed {removed:?}");
        assert!(!dirs[KEEP_SCENES + 3].exists(), "the too old one goes");
        assert!(dirs[KEEP_SCENES + 2].exists(), "the newest stay");
        std::fs::remove_dir_all(&c).unwrap();
    }
}
