//! A scene as one blob — the scene file and every file it reads (meshes, a glTF's buffers) —
//! so any member can hand the room's scene to a joiner that has no copy
//! (`softsync_net::share` carries it). The joiner checks every path before it writes anything:
//! relative, inside the bundle's folder, bounded in count and size; then it loads the scene
//! from its own copy exactly as from a file of its own, and the handshake's digest still
//! decides whether it is the room's.

use std::path::{Component, Path, PathBuf};

use serde::{Deserialize, Serialize};
use softsync_softbody::Mesh;

use super::{Scene, Shape};

/// Largest bundle a peer builds or accepts.
pub const MAX_BUNDLE_BYTES: u64 = 64 << 20;
/// Most files in a bundle.
const MAX_FILES: usize = 1000;
/// Longest path in a bundle.
const MAX_PATH: usize = 255;
/// The bundle format's version.
const FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
struct Bundle {
    format: u32,
    /// The scene file's path in `files`.
    scene: String,
    files: Vec<(String, Vec<u8>)>,
}

/// A path a bundle may hold: relative, `/`-separated plain names, no `..`, no root, no drive.
pub(super) fn check_path(p: &str) -> Result<(), String> {
    let ok = !p.is_empty()
        && p.len() <= MAX_PATH
        && !p.contains('\\')
        && !p.contains(':')
        && !p.contains('\0')
        && Path::new(p)
            .components()
            .all(|c| matches!(c, Component::Normal(_)));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "path {p:?}: a shared scene's files are plain relative paths inside its folder"
        ))
    }
}

impl Scene {
    /// The scene's files as one blob: the scene file as it is on disk and each mesh file (with
    /// a glTF's external buffers), relative to the scene file's folder. A scene whose meshes
    /// lie outside its folder cannot be shared (its files say where).
    pub fn bundle(&self) -> Result<Vec<u8>, String> {
        let dir = self.path.parent().unwrap_or(Path::new("."));
        let scene_name = self
            .path
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| format!("scene {}: not a file name", self.path.display()))?
            .to_owned();
        let mut names = vec![scene_name.clone()];
        for c in &self.classes {
            if let Shape::Mesh { file, .. } = &c.shape {
                check_path(file).map_err(|e| format!("class {:?}: mesh {e}", c.name))?;
                let sub = Path::new(file).parent().unwrap_or(Path::new(""));
                let read = Mesh::files_read(dir.join(file))
                    .map_err(|e| format!("class {:?}: {e}", c.name))?;
                for r in read {
                    let rel = sub.join(&r).to_string_lossy().replace('\\', "/");
                    check_path(&rel).map_err(|e| format!("class {:?}: {e}", c.name))?;
                    if !names.contains(&rel) {
                        names.push(rel);
                    }
                }
            }
        }
        let mut files = Vec::with_capacity(names.len());
        let mut total = 0u64;
        for n in names {
            let p = dir.join(&n);
            let bytes = std::fs::read(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            total += bytes.len() as u64;
            if total > MAX_BUNDLE_BYTES {
                return Err(format!(
                    "scene {}: its files are over {MAX_BUNDLE_BYTES} bytes, too many to share",
                    self.path.display()
                ));
            }
            files.push((n, bytes));
        }
        let b = Bundle {
            format: FORMAT,
            scene: scene_name,
            files,
        };
        bincode::serde::encode_to_vec(&b, bincode::config::standard())
            .map_err(|e| format!("scene bundle: {e}"))
    }

    /// The scene in `bundle`, written under `cache` (in a folder named by its digest, so two
    /// rooms' scenes never mix) and loaded from there. Every path is checked before anything
    /// is written; a malformed bundle is an error, never a panic.
    pub fn from_bundle(bundle: &[u8], cache: &Path) -> Result<Scene, String> {
        if bundle.len() as u64 > MAX_BUNDLE_BYTES {
            return Err(format!("scene bundle of {} bytes: too large", bundle.len()));
        }
        let config = bincode::config::standard().with_limit::<{ MAX_BUNDLE_BYTES as usize }>();
        let (b, used): (Bundle, usize) = bincode::serde::decode_from_slice(bundle, config)
            .map_err(|e| format!("scene bundle: malformed ({e})"))?;
        if used != bundle.len() {
            return Err("scene bundle: bytes after its end".into());
        }
        if b.format != FORMAT {
            return Err(format!(
                "scene bundle: format {} (this peer reads {FORMAT})",
                b.format
            ));
        }
        if b.files.len() > MAX_FILES {
            return Err(format!(
                "scene bundle: {} files, at most {MAX_FILES}",
                b.files.len()
            ));
        }
        for (i, (p, _)) in b.files.iter().enumerate() {
            check_path(p).map_err(|e| format!("scene bundle: {e}"))?;
            if b.files[..i].iter().any(|(q, _)| q == p) {
                return Err(format!("scene bundle: {p:?} twice"));
            }
        }
        if !b.files.iter().any(|(p, _)| *p == b.scene) || !b.scene.ends_with(super::SCENE_EXTENSION)
        {
            return Err(format!(
                "scene bundle: its scene file {:?} is not among its files",
                b.scene
            ));
        }
        let digest = softsync_net::share::sha256(bundle);
        let hex: String = digest[..8].iter().map(|b| format!("{b:02x}")).collect();
        // this user's private folder; no write follows a link (see `cache`)
        super::cache::prepare(cache)?;
        let dir: PathBuf = cache.join(hex);
        for (p, bytes) in &b.files {
            let path = dir.join(p);
            if let Some(parent) = path.parent() {
                super::cache::make_dirs(cache, parent)?;
            }
            write_atomically(&path, bytes)?;
        }
        // the folder's time says when it was last used; the oldest scenes go
        if let Ok(f) = std::fs::File::open(&dir) {
            let _ = f.set_modified(super::cache::wall_now());
        }
        super::cache::clean(cache, &dir);
        // its meshes may name only files of the bundle: a hostile scene must not make this
        // peer read (and then serve to the next joiner) a file of its own
        Scene::load_with(&dir.join(&b.scene), super::file::MeshPaths::Confined)
    }
}

/// Write `path` so that a reader sees the old file or the new one, never half of one: other
/// processes fetching the same scene write the same folder (the same bytes) at the same time.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), String> {
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(format!(".partial-{}-{n}", std::process::id()));
    let tmp = PathBuf::from(tmp);
    // `create_new`: a fresh file (O_EXCL never follows a link planted at its name); the
    // rename then replaces the name itself, never what a link there points to
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .and_then(|mut f| std::io::Write::write_all(&mut f, bytes))
        .and_then(|()| std::fs::rename(&tmp, path))
        .map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            format!("scene cache {}: {e}", path.display())
        })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn assets() -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets"))
    }

    fn cache(test: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("softsync-bundle-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_shipped_scene_travels_as_a_bundle_and_loads_the_same() {
        let scene = Scene::by_name("thesis-room", &assets()).unwrap();
        let blob = scene.bundle().unwrap();
        // The scene file and the bunny's OBJ.
        assert!(blob.len() > 110_000, "{}", blob.len());
        let c = cache("room");
        let back = Scene::from_bundle(&blob, &c).unwrap();
        assert_eq!(back.content_digest(), scene.content_digest());
        assert_eq!(back.name, scene.name);
        assert!(back.path.starts_with(&c));
        let _ = std::fs::remove_dir_all(&c);
    }

    #[test]
    fn peers_unpacking_the_same_scene_at_once_each_load_it_whole() {
        // Several joiners of one room on one machine write the same cache folder together
        // (seen live: a reader found a file another had just truncated).
        let scene = Scene::by_name("bench-ball", &assets()).unwrap();
        let blob = std::sync::Arc::new(scene.bundle().unwrap());
        let c = cache("race");
        for _ in 0..5 {
            let threads: Vec<_> = (0..4)
                .map(|_| {
                    let (blob, c) = (blob.clone(), c.clone());
                    std::thread::spawn(move || Scene::from_bundle(&blob, &c).map(|s| s.name))
                })
                .collect();
            for t in threads {
                assert_eq!(t.join().unwrap().unwrap(), "bench-ball");
            }
        }
        let _ = std::fs::remove_dir_all(&c);
    }

    #[test]
    fn a_bundle_that_would_write_outside_its_folder_or_is_broken_is_refused() {
        let c = cache("hostile");
        let enc =
            |b: &Bundle| bincode::serde::encode_to_vec(b, bincode::config::standard()).unwrap();
        let room = std::fs::read(assets().join("bench-ball.ron")).unwrap();
        let with = |files: Vec<(&str, Vec<u8>)>, scene: &str| Bundle {
            format: FORMAT,
            scene: scene.into(),
            files: files.into_iter().map(|(p, b)| (p.to_owned(), b)).collect(),
        };
        for evil in [
            "../x.ron",
            "/etc/x.ron",
            "a/../../x.ron",
            "c:x.ron",
            "a\\..\\x.ron",
            "",
        ] {
            let b = with(vec![(evil, room.clone())], evil);
            let e = Scene::from_bundle(&enc(&b), &c).unwrap_err();
            assert!(e.contains("plain relative paths"), "{evil:?}: {e}");
        }
        let b = with(
            vec![("a.ron", room.clone()), ("a.ron", room.clone())],
            "a.ron",
        );
        assert!(Scene::from_bundle(&enc(&b), &c)
            .unwrap_err()
            .contains("twice"));
        let b = with(vec![("a.ron", room.clone())], "b.ron");
        assert!(Scene::from_bundle(&enc(&b), &c)
            .unwrap_err()
            .contains("not among"));
        let mut b = with(vec![("a.ron", room.clone())], "a.ron");
        b.format = 9;
        assert!(Scene::from_bundle(&enc(&b), &c)
            .unwrap_err()
            .contains("format 9"));
        // Junk, a truncated bundle, trailing bytes.
        assert!(Scene::from_bundle(&[0xff; 64], &c)
            .unwrap_err()
            .contains("malformed"));
        let good = enc(&with(vec![("a.ron", room.clone())], "a.ron"));
        assert!(Scene::from_bundle(&good[..good.len() - 3], &c).is_err());
        let mut long = good.clone();
        long.push(0);
        assert!(Scene::from_bundle(&long, &c)
            .unwrap_err()
            .contains("after its end"));
        // A scene file that names a mesh the bundle lacks fails as a scene file would.
        let text =
            String::from_utf8(std::fs::read(assets().join("thesis-room.ron")).unwrap()).unwrap();
        let b = with(vec![("room.ron", text.into_bytes())], "room.ron");
        let e = Scene::from_bundle(&enc(&b), &c).unwrap_err();
        assert!(e.contains("bunny.obj"), "{e}");
        // Nothing was written outside the cache.
        assert!(!c.join("../x.ron").exists());
        let _ = std::fs::remove_dir_all(&c);
    }

    #[test]
    fn a_shared_scene_reads_no_file_outside_its_bundle() {
        // A valid mesh of this machine's, outside any bundle: a hostile host's scene names it,
        // by absolute path or with `..`, so that the joiner loads it (and would then serve it
        // to the next joiner as part of the room's scene).
        let c = cache("outside");
        std::fs::create_dir_all(&c).unwrap();
        let secret = c.join("secret.obj");
        std::fs::copy(assets().join("bunny.obj"), &secret).unwrap();
        let text =
            String::from_utf8(std::fs::read(assets().join("thesis-room.ron")).unwrap()).unwrap();
        assert!(text.contains("\"bunny.obj\""));
        // the bundle is unpacked two levels under the cache: <cache>/<digest>/room.ron
        for evil in [
            secret.display().to_string(),
            "../secret.obj".to_string(),
            "./../secret.obj".to_string(),
        ] {
            let scene = text.replace("\"bunny.obj\"", &format!("{evil:?}"));
            let b = Bundle {
                format: FORMAT,
                scene: "room.ron".into(),
                files: vec![("room.ron".into(), scene.clone().into_bytes())],
            };
            let blob = bincode::serde::encode_to_vec(&b, bincode::config::standard()).unwrap();
            let e = Scene::from_bundle(&blob, &c).unwrap_err();
            assert!(
                e.contains("shape.file") && e.contains("plain relative paths"),
                "{evil}: {e}"
            );
            // the same scene file of one's own may name any file (the user's choice)
            let own = c.join("own").join("room.ron");
            std::fs::create_dir_all(own.parent().unwrap()).unwrap();
            std::fs::write(&own, &scene).unwrap();
            Scene::load(&own).unwrap();
        }
        let _ = std::fs::remove_dir_all(&c);
    }
}
