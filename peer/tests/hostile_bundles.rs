//! The scene bundle parser on hostile bytes (issue 32): a valid bundle of the thesis room (its
//! scene file and the bunny's mesh) with bytes flipped, overwritten, cut or repeated, and
//! random bytes. `Scene::from_bundle` gives a scene or an error, never a panic, and writes
//! nothing outside its cache. Seeded, so a failure names its input.
#![allow(clippy::unwrap_used, missing_docs)]

use std::path::PathBuf;

use softsync_net::rng::SeededRng;
use softsync_peer::Scene;

#[test]
fn the_bundle_parser_survives_hostile_bytes_and_writes_only_in_its_cache() {
    let assets = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets"));
    let scene = Scene::by_name("thesis-room", &assets).unwrap();
    let bundle = scene.bundle().unwrap();
    let root = std::env::temp_dir().join(format!("softsync-hostile-bundle-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let cache = root.join("cache");
    // the valid one loads
    Scene::from_bundle(&bundle, &cache).unwrap();
    let mut rng = SeededRng::new(20261128);
    let (mut loaded, mut refused) = (0, 0);
    for k in 0..200 {
        let mut d = bundle.clone();
        match k % 5 {
            0 => {
                for _ in 0..1 + rng.next_u64() % 4 {
                    let i = (rng.next_u64() as usize) % d.len();
                    d[i] ^= 1 << (rng.next_u64() % 8);
                }
            }
            1 => d.truncate((rng.next_u64() as usize) % d.len()),
            2 => {
                // the header: lengths, counts and names live in the first bytes
                let i = (rng.next_u64() as usize) % 64.min(d.len());
                d[i] = rng.next_u64() as u8;
            }
            3 => {
                let i = (rng.next_u64() as usize) % d.len();
                let piece = d[i..(i + 256).min(d.len())].to_vec();
                d.splice(i..i, piece);
            }
            _ => {
                d = (0..rng.next_u64() % 4096)
                    .map(|_| rng.next_u64() as u8)
                    .collect()
            }
        }
        let c = cache.clone();
        match std::panic::catch_unwind(move || Scene::from_bundle(&d, &c)) {
            Err(_) => panic!("bundle input {k} panicked the parser"),
            Ok(Ok(_)) => loaded += 1,
            Ok(Err(_)) => refused += 1,
        }
    }
    println!("hostile bundles: {loaded} loaded, {refused} refused");
    assert!(
        refused > 100,
        "the mutations should break most bundles: {refused}"
    );
    // nothing outside the cache
    let outside: Vec<_> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(outside, vec![std::ffi::OsString::from("cache")]);
    let _ = std::fs::remove_dir_all(&root);
}
