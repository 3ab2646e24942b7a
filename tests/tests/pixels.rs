//! Real pixels: a desktop peer (`softsync join --desktop`) renders the room under Xvfb with
//! Mesa's software Vulkan (lavapipe), saves screenshots with bevy's screenshot API, and a bot
//! on a third peer squeezes the soft box. The test checks the frames are not blank, that the
//! box is on screen where the peer says, that its pixels do not change while it rests, and
//! that they do when it is squeezed; and, with the camera on the bunny, that a bot's tear
//! reaches the renderer (the drawn mesh gains triangles and an open rim) and opens a slit
//! whose pixels change; and that two desktop hands stretch the bunny and keep its halves when
//! another peer's cutter splits it between them.
//!
//! Needs: the binary built with `--features desktop` (scripts/test builds `--features vr`,
//! which includes it), `Xvfb`, `mesa-vulkan-drivers` (.ci/run installs them), and a network
//! namespace (WebRTC; scripts/netns-run). It starts its own X server and bounds every wait.
#![allow(clippy::unwrap_used, clippy::disallowed_methods, missing_docs)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{embedded_host, field, require_netns, rollback_checks, scratch, send_signal, Proc};

/// An Xvfb server on a free display, killed when dropped.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    fn start(dir: &Path) -> Xvfb {
        let log = std::fs::File::create(dir.join("xvfb.log")).unwrap();
        for n in 0..20u32 {
            let num = 90 + (std::process::id() + n * 7) % 400;
            if Path::new(&format!("/tmp/.X11-unix/X{num}")).exists()
                || Path::new(&format!("/tmp/.X{num}-lock")).exists()
            {
                continue;
            }
            let child = match Command::new("Xvfb")
                .args([
                    format!(":{num}").as_str(),
                    "-screen",
                    "0",
                    "640x480x24",
                    "-nolisten",
                    "tcp",
                ])
                .stdout(Stdio::null())
                .stderr(Stdio::from(log.try_clone().unwrap()))
                .spawn()
            {
                Ok(c) => c,
                Err(e) => {
                    panic!("cannot start Xvfb ({e}): install the xvfb package (.ci/run does)")
                }
            };
            let mut x = Xvfb {
                child,
                display: format!(":{num}"),
            };
            let start = Instant::now();
            while start.elapsed() < Duration::from_secs(10) {
                if Path::new(&format!("/tmp/.X11-unix/X{num}")).exists() {
                    return x;
                }
                if x.child.try_wait().unwrap().is_some() {
                    break; // taken meanwhile: try the next number
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = x.child.kill();
        }
        panic!(
            "no Xvfb display came up; see {}",
            dir.join("xvfb.log").display()
        );
    }
}

impl Xvfb {
    /// The environment of a peer drawing on this display with Mesa's software Vulkan
    /// (whatever other Vulkan drivers are installed), plus `extra`.
    fn env<'a>(&'a self, extra: &[(&'a str, &'a str)]) -> Vec<(&'a str, &'a str)> {
        let mut v = vec![
            ("DISPLAY", self.display.as_str()),
            ("WGPU_BACKEND", "vulkan"),
            (
                "VK_ICD_FILENAMES",
                "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json",
            ),
        ];
        v.extend_from_slice(extra);
        v
    }
}

/// A host with embedded signaling on a free port, and its URL.
fn host(dir: &Path, room: &str) -> (Proc, String) {
    embedded_host(dir, room, &["--duration", "150"])
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// One saved frame and what the peer measured when it took it, for one soft body.
#[derive(Debug, Clone)]
struct Frame {
    n: u32,
    path: PathBuf,
    deform_mm: f64,
    /// The body's screen box (x0, y0, x1, y1), pixels.
    bbox: [f64; 4],
    /// Triangles of the mesh the renderer draws for it.
    tris: usize,
    /// The screen box of that mesh's open rim (a tear's slit), if it has one.
    rim: Option<[f64; 4]>,
}

fn px_box(v: &str) -> [f64; 4] {
    let b: Vec<f64> = v.split(',').map(|v| v.parse().unwrap()).collect();
    [b[0], b[1], b[2], b[3]]
}

/// The frames saved so far, as seen for the soft body `kind`.
fn frames_of(p: &Proc, kind: &str) -> Vec<Frame> {
    let px = format!("{kind}_px=");
    p.stdout()
        .lines()
        .filter(|l| l.starts_with("screenshot ") && l.contains(&px))
        .map(|l| Frame {
            n: field(l, "n").parse().unwrap(),
            path: PathBuf::from(field(l, "path")),
            deform_mm: field(l, &format!("{kind}_deform_mm")).parse().unwrap(),
            bbox: px_box(field(l, &format!("{kind}_px"))),
            // The drawn mesh, once the view has made it.
            tris: if l.contains(&format!(" {kind}_tris=")) {
                field(l, &format!("{kind}_tris")).parse().unwrap()
            } else {
                0
            },
            rim: l
                .contains(&format!(" {kind}_rim_px="))
                .then(|| px_box(field(l, &format!("{kind}_rim_px")))),
        })
        .collect()
}

fn frames(p: &Proc) -> Vec<Frame> {
    frames_of(p, "softbox")
}

/// A desktop peer joining `room`, its camera on `focus`, saving a 320×240 frame every 0.5 s.
fn desktop_peer(dir: &Path, x: &Xvfb, url: &str, room: &str, focus: &str) -> Proc {
    desktop_peer_with(dir, x, url, room, focus, &[])
}

/// As [`desktop_peer`], with more arguments (a bot script on its hands).
fn desktop_peer_with(
    dir: &Path,
    x: &Xvfb,
    url: &str,
    room: &str,
    focus: &str,
    extra: &[&str],
) -> Proc {
    let shots = dir.join("shots");
    let shots_s = shots.to_str().unwrap().to_owned();
    let mut args = vec![
        "join",
        "--room",
        room,
        "--signal",
        url,
        "--desktop",
        "--window",
        "320x240",
        "--focus",
        focus,
        "--hide-avatars",
        "--no-hud",
        "--screenshot-dir",
        &shots_s,
        "--screenshot-every",
        "0.5",
        "--screenshots",
        "400",
        "--duration",
        "140",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    Proc::spawn_env(dir, "desktop", &args, &x.env(&[]))
}

/// Wait until the desktop peer has saved `n` frames showing `kind` (the software renderer's
/// first frame compiles every pipeline; bounded generously).
fn first_frames(desktop: &mut Proc, kind: &str, n: usize) -> Vec<Frame> {
    let start = Instant::now();
    while frames_of(desktop, kind).len() < n {
        if let Some(s) = desktop.child.try_wait().unwrap() {
            panic!("the desktop peer exited ({s})\n{}", desktop.logs());
        }
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "fewer than {n} screenshots within 90 s\n{}",
            desktop.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let f = frames_of(desktop, kind);
    println!(
        "first frames after {:.1} s: {:?}",
        start.elapsed().as_secs_f64(),
        f
    );
    f
}

struct Rgb {
    w: u32,
    h: u32,
    px: Vec<u8>,
}

impl Rgb {
    fn load(path: &Path) -> Rgb {
        let dec = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
        ));
        let mut r = dec.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        buf.truncate(info.buffer_size());
        Rgb {
            w: info.width,
            h: info.height,
            px: buf,
        }
    }

    fn at(&self, x: u32, y: u32) -> [u8; 3] {
        let i = ((y * self.w + x) * 3) as usize;
        [self.px[i], self.px[i + 1], self.px[i + 2]]
    }

    /// Pixels in a box (clamped to the image), with a margin.
    fn region(&self, b: [f64; 4], margin: f64) -> impl Iterator<Item = (u32, u32)> + '_ {
        let x0 = (b[0] - margin).max(0.0) as u32;
        let y0 = (b[1] - margin).max(0.0) as u32;
        let x1 = ((b[2] + margin) as u32).min(self.w - 1);
        let y1 = ((b[3] + margin) as u32).min(self.h - 1);
        (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| (x, y)))
    }
}

/// The soft box's orange (0.95, 0.5, 0.1) under any lighting: red well above blue, green
/// between. Avatars and the table are other hues.
fn is_orange(c: [u8; 3]) -> bool {
    let [r, g, b] = c.map(i32::from);
    r > 60 && r - b > 50 && g > b && r > g + 15
}

fn union(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0].min(b[0]),
        a[1].min(b[1]),
        a[2].max(b[2]),
        a[3].max(b[3]),
    ]
}

/// Fraction of pixels in `b` (with a 4-pixel margin) that differ by more than 30 (sum over
/// channels), how many that is, and how many of those are box-coloured in either frame (the
/// change is on the box, not around it).
fn changed(a: &Rgb, c: &Rgb, b: [f64; 4]) -> (f64, usize, usize) {
    let (n, diff, on_box) = count_changed(a, c, b, 4.0);
    (diff as f64 / n.max(1) as f64, diff, on_box)
}

/// Pixels in `b` (with `margin`), how many differ by more than 30 (sum over channels), and
/// how many of those are box-coloured in either frame.
fn count_changed(a: &Rgb, c: &Rgb, b: [f64; 4], margin: f64) -> (usize, usize, usize) {
    let (mut n, mut diff, mut on_box) = (0usize, 0usize, 0usize);
    for (x, y) in a.region(b, margin) {
        let (p, q) = (a.at(x, y), c.at(x, y));
        n += 1;
        let d: i32 = (0..3)
            .map(|i| (i32::from(p[i]) - i32::from(q[i])).abs())
            .sum();
        if d > 30 {
            diff += 1;
            if is_orange(p) || is_orange(q) {
                on_box += 1;
            }
        }
    }
    (n, diff, on_box)
}

#[test]
fn desktop_peer_renders_the_room_and_a_squeeze_changes_the_soft_box_pixels() {
    require_netns();
    let dir = scratch("pixels");
    let x = Xvfb::start(&dir);
    let (host, url) = host(&dir, "pixels");
    let mut desktop = desktop_peer(&dir, &x, &url, "pixels", "softbox");
    // Rendering works: a few frames at rest first.
    let rest_frames = first_frames(&mut desktop, "softbox", 4);
    // Now a bot squeezes the box and holds it.
    let mut bot = Proc::spawn(
        &dir,
        "bot",
        &[
            "join",
            "--room",
            "pixels",
            "--signal",
            &url,
            "--bot",
            // From the front (the box is at 0.32, 0.82, 0.05; `--focus` looks at it from +z):
            // the face the camera sees is pressed in.
            "wait 0.5; move right 0.32 0.83 0.3 in 0.6; reach right softbox in 0.5; grab right; \
             squeeze right 0.03 in 0.5; wait 30; release right",
            "--duration",
            "60",
            "--quiet",
        ],
    );
    bot.wait_line("grabbed object", Duration::from_secs(30));
    // At rest the box already sags a little under gravity: the squeeze adds to that.
    let rest_deform = rest_frames.last().unwrap().deform_mm;
    let last_rest = rest_frames.last().unwrap().n;
    let start = Instant::now();
    let squeezed = loop {
        if let Some(f) = frames(&desktop)
            .into_iter()
            .find(|f| f.n > last_rest && f.deform_mm > rest_deform + 8.0)
        {
            // One more frame so the squeeze is well under way.
            let n = f.n + 2;
            if let Some(g) = frames(&desktop).into_iter().find(|g| g.n == n) {
                break g;
            }
        }
        assert!(
            start.elapsed() < Duration::from_secs(40),
            "the desktop peer never showed the box squeezed 8 mm beyond rest\n{}\n{}",
            desktop.logs(),
            bot.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    // Two frames at rest, before the bot joined.
    let (r1, r2) = (
        &rest_frames[rest_frames.len() - 2],
        &rest_frames[rest_frames.len() - 1],
    );
    assert!(
        (r1.deform_mm - r2.deform_mm).abs() < 0.5,
        "the box was not at rest: {r1:?} {r2:?}"
    );
    let (a, b, s) = (
        Rgb::load(&r1.path),
        Rgb::load(&r2.path),
        Rgb::load(&squeezed.path),
    );
    assert_eq!((a.w, a.h), (320, 240), "screenshot size");
    // Not blank: many colours, real contrast.
    let lum: Vec<f64> =
        a.px.chunks(3)
            .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
            .collect();
    let mean = lum.iter().sum::<f64>() / lum.len() as f64;
    let sd = (lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lum.len() as f64).sqrt();
    let colours: std::collections::HashSet<[u8; 3]> =
        a.px.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
    println!(
        "rest frame: luminance mean {mean:.1} sd {sd:.1}, {} colours",
        colours.len()
    );
    assert!(sd > 8.0, "the frame is nearly uniform (sd {sd:.1})");
    assert!(
        colours.len() > 50,
        "the frame has {} colours",
        colours.len()
    );
    // The box is where the peer says, in its colour.
    let orange = a
        .region(r1.bbox, 0.0)
        .filter(|&(x, y)| is_orange(a.at(x, y)))
        .count();
    let area = ((r1.bbox[2] - r1.bbox[0]) * (r1.bbox[3] - r1.bbox[1])).max(1.0);
    println!("box at {:?}: {orange} orange pixels of {area:.0}", r1.bbox);
    assert!(
        orange as f64 > 0.3 * area && orange > 200,
        "the soft box is not drawn where it projects ({orange} orange pixels in {area:.0})"
    );
    // At rest nothing changes; squeezed, the box's pixels do.
    let region = union(r1.bbox, squeezed.bbox);
    let (still, _, still_box) = changed(&a, &b, region);
    let (moved, _, moved_box) = changed(&a, &s, region);
    println!(
        "box region {region:?}: at rest {:.2}% changed ({still_box} on the box); \
         squeezed by {:.1} mm: {:.2}% changed ({moved_box} on the box)",
        still * 100.0,
        squeezed.deform_mm,
        moved * 100.0
    );
    assert!(
        still < 0.01,
        "pixels changed while the box rested: {:.2}%",
        still * 100.0
    );
    assert!(
        moved > 0.05 && moved_box > 200,
        "the squeeze did not change the box's pixels enough: {:.2}%, {moved_box} on the box",
        moved * 100.0
    );
    // A slow frame never slows the room: the desktop peer's frames on the software renderer
    // take tens to hundreds of ms, yet its RTT to the host (pumped by its network thread) is
    // within a few ms of the headless bot's.
    let host_id = host.peer_id().to_string();
    let mut finals = Vec::new();
    for p in [&mut desktop, &mut bot] {
        send_signal("-TERM", p);
        p.wait_exit(Duration::from_secs(20));
        let l = p.wait_line("final stats", Duration::from_secs(1));
        let rtt: f64 = field(&l, "rtts")
            .split(',')
            .find_map(|e| e.strip_prefix(&format!("{host_id}:")))
            .unwrap_or_else(|| panic!("no RTT to the host in {l:?}"))
            .parse()
            .unwrap();
        finals.push((rtt, field(&l, "frame_ms").to_owned()));
    }
    let ((d_rtt, d_frames), (b_rtt, b_frames)) = (&finals[0], &finals[1]);
    println!(
        "RTT to the host: desktop {d_rtt:.1} ms (frames p50/max {d_frames} ms), \
         bot {b_rtt:.1} ms (frames {b_frames} ms)"
    );
    assert!(
        *d_rtt < b_rtt + 15.0,
        "the desktop's RTT follows its frames: {d_rtt} ms against the bot's {b_rtt} ms \
         (desktop frames {d_frames} ms)"
    );
}

#[test]
fn desktop_peer_draws_a_torn_bunny_with_its_slit_open() {
    require_netns();
    let dir = scratch("pixels-tear");
    let x = Xvfb::start(&dir);
    let (_host, url) = host(&dir, "tear");
    let mut desktop = desktop_peer(&dir, &x, &url, "tear", "bunny");
    let before = first_frames(&mut desktop, "bunny", 4);
    let b0 = before.last().unwrap().clone();
    assert!(
        b0.rim.is_none() && b0.tris > 1000,
        "the whole bunny is not drawn closed: {b0:?}"
    );
    // A bot takes the bunny and tears its top from left to right (the blade points up from
    // 3 cm above the center, so the slit runs across the back and head the camera sees).
    let bot = Proc::spawn(
        &dir,
        "bot",
        &[
            "join",
            "--room",
            "tear",
            "--signal",
            &url,
            "--bot",
            "wait 0.5; own bunny; \
             tear right bunny -0.06 0.03 0 -0.03 0.03 0.004 0 0.03 0 0.03 0.03 -0.004 0.06 0.03 0 in 0.1; \
             wait 30",
            "--duration",
            "60",
            "--quiet",
        ],
    );
    bot.wait_line("tore object", Duration::from_secs(40));
    // The torn mesh reaches the renderer: wait for two frames in a row that draw it with the
    // same triangles and the body at rest.
    let start = Instant::now();
    let torn = loop {
        let f = frames_of(&desktop, "bunny");
        let pair = f.windows(2).rev().find(|w| {
            w[0].n > b0.n
                && w[0].rim.is_some()
                && w[0].tris == w[1].tris
                && (w[0].deform_mm - w[1].deform_mm).abs() < 0.5
        });
        if let Some(w) = pair {
            break w[1].clone();
        }
        assert!(
            start.elapsed() < Duration::from_secs(40),
            "the desktop peer never drew the bunny torn and at rest\n{:?}\n{}\n{}",
            f.last(),
            desktop.logs(),
            bot.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let rim = torn.rim.unwrap();
    println!("before {b0:?}\ntorn {torn:?}");
    assert!(
        torn.tris > b0.tris,
        "the torn mesh has no more triangles than the whole one"
    );
    // The slit is on screen, inside the bunny's box, and a few pixels wide at least.
    assert!(
        rim[0] >= torn.bbox[0] - 1.0
            && rim[1] >= torn.bbox[1] - 1.0
            && rim[2] <= torn.bbox[2] + 1.0
            && rim[3] <= torn.bbox[3] + 1.0
            && rim[2] - rim[0] > 20.0,
        "the slit's rim {rim:?} is not a line across the bunny {:?}",
        torn.bbox
    );
    // Through the slit the camera sees past the bunny's skin: its pixels change.
    let (a, t) = (Rgb::load(&b0.path), Rgb::load(&torn.path));
    let (frac, diff, _) = changed(&a, &t, rim);
    println!(
        "slit region {rim:?}: {diff} pixels ({:.1}%) changed",
        frac * 100.0
    );
    assert!(
        diff >= 40 && frac >= 0.03,
        "the torn bunny looks like the whole one around its slit: {diff} pixels ({:.1}%) changed",
        frac * 100.0
    );
}

#[test]
fn vr_without_a_runtime_says_why_and_opens_the_desktop_peer() {
    require_netns();
    let dir = scratch("vr-fallback");
    let shots = dir.join("shots");
    let x = Xvfb::start(&dir);
    let (_host, url) = host(&dir, "fallback");
    let shots_s = shots.to_str().unwrap().to_owned();
    let mut peer = Proc::spawn_env(
        &dir,
        "vr",
        &[
            "join",
            "--room",
            "fallback",
            "--signal",
            &url,
            "--vr",
            "--window",
            "160x120",
            "--screenshot-dir",
            &shots_s,
            "--screenshots",
            "1",
            "--duration",
            "6",
            "--quiet",
        ],
        // No runtime, whatever this machine has installed.
        &x.env(&[("XR_RUNTIME_JSON", "/nonexistent/openxr_runtime.json")]),
    );
    let code = peer.wait_exit(Duration::from_secs(60));
    let err = std::fs::read_to_string(&peer.err).unwrap();
    assert_eq!(code, 0, "{}", peer.logs());
    let reason = err
        .lines()
        .find(|l| l.starts_with("vr: ") && !l.contains("opening the desktop"));
    println!("{reason:?}");
    assert!(
        reason.is_some_and(|r| r.contains("OpenXR")),
        "no reason given: {}",
        peer.logs()
    );
    assert!(
        err.contains("vr: opening the desktop peer instead"),
        "{}",
        peer.logs()
    );
    // The desktop peer joined and drew a frame.
    peer.wait_line("joined host=", Duration::from_secs(1));
    let shot = peer.wait_line("screenshot n=0", Duration::from_secs(1));
    assert!(
        Path::new(field(&shot, "path")).exists(),
        "no screenshot file: {shot}"
    );
}

/// Fraction of the pixels in box `b` (no margin) that differ by more than 30 (sum over
/// channels) between two frames, and how many.
fn diff_in(a: &Rgb, c: &Rgb, b: [f64; 4]) -> (f64, usize) {
    let (n, diff, _) = count_changed(a, c, b, 0.0);
    (diff as f64 / n.max(1) as f64, diff)
}

/// Per saved frame: its number, the screen box of every piece of `kind` (largest first), and
/// its file.
fn pieces_of(p: &Proc, kind: &str) -> Vec<(u32, Vec<[f64; 4]>, PathBuf)> {
    let key = format!("{kind}_px=");
    p.stdout()
        .lines()
        .filter(|l| l.starts_with("screenshot ") && l.contains(&format!(" {kind}_count=")))
        .map(|l| {
            let mut boxes: Vec<[f64; 4]> = l
                .split_whitespace()
                .filter_map(|w| w.strip_prefix(key.as_str()))
                .map(px_box)
                .collect();
            let area = |b: &[f64; 4]| (b[2] - b[0]) * (b[3] - b[1]);
            boxes.sort_by(|a, b| area(b).total_cmp(&area(a)));
            (
                field(l, "n").parse().unwrap(),
                boxes,
                PathBuf::from(field(l, "path")),
            )
        })
        .collect()
}

/// Issue 31's pixels: the desktop peer's two hands hold the bunny by its left and right
/// sides and pull it apart — the stretched frame differs from the rest frame on both sides,
/// where the bunny grew — then a bot on another peer, which owns nothing, sweeps its cutter
/// through the bunny between the hands (the cut gesture, `slice`): the desktop draws the
/// pieces (two, or three when an ear comes off too), split where the cutter went, each half
/// still stretched in its hand (no piece tips or collapses), and the frame changes along the
/// seam.
#[test]
fn two_desktop_hands_stretch_the_bunny_and_a_cut_between_them_splits_it_in_their_hands() {
    require_netns();
    let dir = scratch("pixels-stretch");
    let x = Xvfb::start(&dir);
    let (host, url) = host(&dir, "stretch");
    let mut desktop = desktop_peer_with(
        &dir,
        &x,
        &url,
        "stretch",
        "bunny",
        &[
            "--bot",
            "wait 3; reach left bunny at -0.07 0.01 0 in 0.6; grab left; \
             reach right bunny at 0.07 0.01 0 in 0.6; grab right; \
             pull left -0.025 0 0 in 1; pull right 0.025 0 0 in 1; wait 100",
        ],
    );
    let rest = first_frames(&mut desktop, "bunny", 2);
    let r0 = rest[0].clone();
    assert!(r0.deform_mm < 8.0, "not at rest: {r0:?}"); // its sag under gravity
                                                        // stretched: the bunny's box at least 20 px wider, three frames in a row (1 s) alike
    let start = Instant::now();
    let stretched = loop {
        let f = frames_of(&desktop, "bunny");
        let w0 = r0.bbox[2] - r0.bbox[0];
        let still = |a: &Frame, b: &Frame| {
            (a.deform_mm - b.deform_mm).abs() < 1.0
                && (0..4).all(|k| (a.bbox[k] - b.bbox[k]).abs() < 1.5)
        };
        let run = f.windows(3).rev().find(|w| {
            w[0].bbox[2] - w[0].bbox[0] > w0 + 20.0 && still(&w[0], &w[1]) && still(&w[1], &w[2])
        });
        if let Some(w) = run {
            break w[2].clone();
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the desktop peer never drew the bunny stretched\n{:?}\n{}\n{}",
            f.last(),
            desktop.logs(),
            host.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    println!("rest {r0:?}\nstretched {stretched:?}");
    let (a, s) = (Rgb::load(&r0.path), Rgb::load(&stretched.path));
    // where it grew: left of the rest box and right of it
    let (y0, y1) = (r0.bbox[1], r0.bbox[3]);
    let left = [stretched.bbox[0], y0, r0.bbox[0] - 1.0, y1];
    let right = [r0.bbox[2] + 1.0, y0, stretched.bbox[2], y1];
    let ((fl, dl), (fr, dr)) = (diff_in(&a, &s, left), diff_in(&a, &s, right));
    println!(
        "grew left {left:?}: {dl} pixels ({:.0}%) changed; right {right:?}: {dr} ({:.0}%)",
        fl * 100.0,
        fr * 100.0
    );
    assert!(
        stretched.bbox[0] < r0.bbox[0] - 2.0 && stretched.bbox[2] > r0.bbox[2] + 2.0,
        "not stretched both ways: {:?} from {:?}",
        stretched.bbox,
        r0.bbox
    );
    assert!(
        dl >= 40 && dr >= 40,
        "the frame did not change where the bunny grew"
    );
    // the cut between the hands, by a peer that owns nothing
    let bot = Proc::spawn(
        &dir,
        "slicer",
        &[
            "join",
            "--room",
            "stretch",
            "--signal",
            &url,
            "--bot",
            "wait 0.5; slice right bunny 0 0.02 0.14 0 0.02 -0.14 in 1; wait 40",
            "--duration",
            "60",
            "--quiet",
        ],
    );
    bot.wait_line("sliced bunny", Duration::from_secs(40));
    // the two largest pieces side by side, split where the cutter went (the middle third of
    // the stretched bunny), each still stretched in its hand: two frames in a row alike
    let (third0, third1) = (
        stretched.bbox[0] + (stretched.bbox[2] - stretched.bbox[0]) / 3.0,
        stretched.bbox[2] - (stretched.bbox[2] - stretched.bbox[0]) / 3.0,
    );
    let split = |b: &[[f64; 4]]| -> Option<([f64; 4], [f64; 4])> {
        if b.len() < 2 {
            return None;
        }
        let (l, r) = if b[0][0] < b[1][0] {
            (b[0], b[1])
        } else {
            (b[1], b[0])
        };
        let meet = (r[0] - l[2]).abs() < 6.0 && l[2] > third0 && r[0] < third1;
        let held = l[0] < stretched.bbox[0] + 4.0 && r[2] > stretched.bbox[2] - 4.0;
        (meet && held).then_some((l, r))
    };
    let start = Instant::now();
    let (cut_path, halves) = loop {
        let f = pieces_of(&desktop, "bunny");
        let pair = f.windows(2).rev().find(|w| {
            split(&w[0].1).is_some()
                && split(&w[1].1).is_some()
                && (0..4).all(|k| (w[0].1[0][k] - w[1].1[0][k]).abs() < 1.5)
        });
        if let Some(w) = pair {
            break (w[1].2.clone(), split(&w[1].1).unwrap());
        }
        assert!(
            start.elapsed() < Duration::from_secs(40),
            "the desktop peer never drew the bunny split in its hands\n{:?}\n{}\n{}\n{}",
            f.last(),
            desktop.logs(),
            bot.logs(),
            host.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    // the seam: where the halves meet, the frame differs from the stretched one (the cut's
    // faces, their shading), over the bunny's middle rows
    let seam_x = 0.5 * (halves.0[2] + halves.1[0]);
    let (y0, y1) = (
        r0.bbox[1] + 0.3 * (r0.bbox[3] - r0.bbox[1]),
        r0.bbox[1] + 0.7 * (r0.bbox[3] - r0.bbox[1]),
    );
    let seam = [seam_x - 3.0, y0, seam_x + 3.0, y1];
    let c = Rgb::load(&cut_path);
    let (ds, n) = diff_in(&s, &c, seam);
    println!(
        "cut: halves {:?} and {:?}; the seam {seam:?}: {n} pixels ({:.0}%) changed",
        halves.0,
        halves.1,
        ds * 100.0
    );
    assert!(
        n >= 15,
        "the cut does not show where the halves meet: {n} pixels changed"
    );
}

/// Pure green (the speaking indicator's gizmo lines, unlit): nothing else in the room is.
fn is_green(c: [u8; 3]) -> bool {
    c[1] > 170 && c[0] < 90 && c[2] < 90
}

#[test]
fn the_speaking_indicator_floats_over_the_talking_bots_head() {
    require_netns();
    let dir = scratch("pixels-voice");
    let raw = dir.join("said.wav");
    softsync_voice::files::speak(
        "Hold the clamp steady while I cut along the line, then lift it gently.",
        140,
        &raw,
    )
    .unwrap_or_else(|e| panic!("{e} (.ci/run installs it)"));
    let x = Xvfb::start(&dir);
    let (_host, url) = host(&dir, "pixels-voice");
    let said = raw.to_str().unwrap().to_owned();
    let speaker = Proc::spawn(
        &dir,
        "speaker",
        &[
            "join",
            "--room",
            "pixels-voice",
            "--signal",
            &url,
            "--quiet",
            "--voice-in",
            &said,
            "--voice-after",
            "12",
            "--voice-every",
            "7",
            "--duration",
            "60",
            // its head over the middle of the table, where the desktop peer looks
            "--bot",
            "move head 0 0.9 0 in 1; wait 100",
            "--name",
            "Dr Lee",
            "--colour",
            "ff20ff",
        ],
    );
    let spk = speaker.peer_id();
    let shots = dir.join("shots");
    let shots_s = shots.to_str().unwrap().to_owned();
    let mut desktop = Proc::spawn_env(
        &dir,
        "desktop",
        &[
            "join",
            "--room",
            "pixels-voice",
            "--signal",
            &url,
            "--desktop",
            "--window",
            "320x240",
            "--no-hud",
            "--voice",
            "--screenshot-dir",
            &shots_s,
            "--screenshot-every",
            "0.5",
            "--screenshots",
            "200",
            "--duration",
            "60",
            "--quiet",
        ],
        &x.env(&[]),
    );
    // frames without speech first, then frames that name the speaker
    let start = Instant::now();
    let lines = |p: &Proc| -> Vec<String> {
        p.stdout()
            .lines()
            .filter(|l| l.starts_with("screenshot "))
            .map(str::to_owned)
            .collect()
    };
    loop {
        let l = lines(&desktop);
        if l.iter()
            .filter(|l| l.contains(&format!("speaking={spk}")))
            .count()
            >= 3
        {
            break;
        }
        if let Some(s) = desktop.child.try_wait().unwrap() {
            panic!("the desktop peer exited ({s})\n{}", desktop.logs());
        }
        assert!(
            start.elapsed() < Duration::from_secs(110),
            "no frame showed peer {spk} speaking within 110 s\n{}\n{}",
            desktop.logs(),
            speaker.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let all = lines(&desktop);
    let quiet: Vec<&String> = all.iter().filter(|l| !l.contains("speaking=")).collect();
    let talking: Vec<&String> = all
        .iter()
        .filter(|l| l.contains(&format!("speaking={spk}")))
        .collect();
    assert!(!quiet.is_empty(), "no frame before the bot spoke");
    // before: no green anywhere
    for l in &quiet {
        let img = Rgb::load(Path::new(field(l, "path")));
        let green = img
            .region([0.0, 0.0, 319.0, 239.0], 0.0)
            .filter(|(x, y)| is_green(img.at(*x, *y)))
            .count();
        assert!(green < 5, "{green} green pixels while nobody spoke: {l}");
    }
    // while it speaks: green inside the indicator's box, above where its head is drawn
    let mut seen = 0;
    for l in &talking {
        let Some(bx) = l
            .split_whitespace()
            .find_map(|w| w.strip_prefix("speaking_px="))
        else {
            continue;
        };
        let b = px_box(bx);
        let img = Rgb::load(Path::new(field(l, "path")));
        let inside = img
            .region(b, 2.0)
            .filter(|(x, y)| is_green(img.at(*x, *y)))
            .count();
        println!("{}: {inside} green pixels in {b:?}", field(l, "n"));
        if inside >= 10 {
            seen += 1;
        }
    }
    assert!(
        seen >= 2,
        "the indicator was not drawn where the peer said\n{}",
        desktop.logs()
    );
    // its name above its head, in its colour (magenta text on the label's dark ground)
    let named: Vec<&String> = all
        .iter()
        .filter(|l| l.contains(&format!("label={spk}")))
        .collect();
    assert!(
        !named.is_empty(),
        "no frame labelled peer {spk}\n{}",
        desktop.logs()
    );
    let mut labelled = 0;
    for l in named.iter().rev().take(4) {
        let (at, magenta) = magenta_at_label(l, 170);
        println!(
            "{}: {magenta} magenta pixels around the label at {at:?}",
            field(l, "n")
        );
        if magenta >= 8 {
            labelled += 1;
        }
    }
    assert!(
        labelled >= 2,
        "the name was not drawn above the head\n{}",
        desktop.logs()
    );
    drop(speaker);
}

/// `--world-labels`: a named bot's name as a card in the world above its head (how a headset
/// shows names; the VR smoke test sees the card made), drawn in its colour where the head is
/// seen from the desktop camera.
#[test]
fn a_name_card_floats_in_the_world_over_a_named_bots_head() {
    require_netns();
    let dir = scratch("pixels-card");
    let x = Xvfb::start(&dir);
    let (_host, url) = host(&dir, "pixels-card");
    let bot = Proc::spawn(
        &dir,
        "bot",
        &[
            "join",
            "--room",
            "pixels-card",
            "--signal",
            &url,
            "--quiet",
            "--duration",
            "60",
            "--bot",
            "move head 0 0.9 0 in 1; wait 100",
            "--name",
            "Dr Lee",
            "--colour",
            "ff20ff",
        ],
    );
    let who = bot.peer_id();
    let shots = dir.join("shots");
    let shots_s = shots.to_str().unwrap().to_owned();
    let desktop = Proc::spawn_env(
        &dir,
        "desktop",
        &[
            "join",
            "--room",
            "pixels-card",
            "--signal",
            &url,
            "--desktop",
            "--window",
            "320x240",
            "--no-hud",
            "--world-labels",
            "--hide-avatars",
            "--screenshot-dir",
            &shots_s,
            "--screenshot-every",
            "0.5",
            "--screenshots",
            "200",
            "--duration",
            "60",
            "--quiet",
        ],
        &x.env(&[]),
    );
    let start = Instant::now();
    let mut labelled = 0;
    let mut checked = std::collections::BTreeSet::new();
    while labelled < 2 {
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "no frame showed the card over peer {who}'s head\n{}",
            desktop.logs()
        );
        let out = desktop.stdout();
        for l in out
            .lines()
            .filter(|l| l.starts_with("screenshot ") && l.contains(&format!("label={who}")))
        {
            if !checked.insert(l.to_owned()) {
                continue;
            }
            let (at, magenta) = magenta_at_label(l, 150);
            if !(0.0..320.0).contains(&at[0]) || !(0.0..240.0).contains(&at[1]) {
                continue; // the card is off the screen
            }
            // (the avatars are hidden: the bot's magenta head and hands cannot count)
            println!(
                "{}: {magenta} magenta pixels on the card at {at:?}",
                field(l, "n")
            );
            if magenta >= 6 {
                labelled += 1;
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        desktop
            .stdout()
            .contains(&format!("view label peer={who} world=true")),
        "{}",
        desktop.logs()
    );
}

/// Where a screenshot line says a peer's label is anchored, and the magenta pixels (R and B
/// over `min`, G under 110) in an 80×28 box around it.
fn magenta_at_label(line: &str, min: u8) -> (Vec<f64>, usize) {
    let at: Vec<f64> = field(line, "label_at")
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let img = Rgb::load(Path::new(field(line, "path")));
    let n = img
        .region(
            [at[0] - 40.0, at[1] - 14.0, at[0] + 40.0, at[1] + 14.0],
            0.0,
        )
        .filter(|(x, y)| {
            let c = img.at(*x, *y);
            c[0] > min && c[2] > min && c[1] < 110
        })
        .count();
    (at, n)
}

#[test]
fn a_desktop_peer_stands_in_a_rollback_room_draws_the_bots_throw_and_agrees_with_it() {
    require_netns();
    let dir = scratch("pixels-rollback");
    let x = Xvfb::start(&dir);
    // The host is a bot that reaches for the soft box (the scene's object 3), grips it, lifts
    // it and throws it, every 4 s, starting once the desktop peer is a player.
    let (host, url) = embedded_host(
        &dir,
        "rbpx",
        &[
            "--sync",
            "rollback",
            "--bot",
            "throw:3",
            "--duration",
            "150",
        ],
    );
    let shots = dir.join("shots");
    let shots_s = shots.to_str().unwrap().to_owned();
    let mut desktop = Proc::spawn_env(
        &dir,
        "desktop",
        &[
            "join",
            "--room",
            "rbpx",
            "--signal",
            &url,
            "--sync",
            "rollback",
            "--desktop",
            "--window",
            "320x240",
            "--focus",
            "softbox",
            "--no-hud",
            "--screenshot-dir",
            &shots_s,
            "--screenshot-every",
            "0.25",
            "--screenshots",
            "400",
            "--duration",
            "140",
            "--quiet",
        ],
        &x.env(&[]),
    );
    // Both are players of one epoch.
    let me = desktop.wait_line("joining room=", Duration::from_secs(60));
    let me = field(&me, "peer").to_owned();
    let start = Instant::now();
    loop {
        let both = desktop
            .stdout()
            .lines()
            .any(|l| l.starts_with("epoch ") && field(l, "players").split(',').count() == 2);
        if both {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no epoch of two players on the desktop peer\n{}\n{}",
            desktop.logs(),
            host.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    // Frames of two players showing the box, then the bot's grab of it (in the desktop's view
    // too: a grab is a frame of the shared world, the same everywhere).
    let shot_lines = |p: &Proc| -> Vec<String> {
        p.stdout()
            .lines()
            .filter(|l| {
                l.starts_with("screenshot ")
                    && field(l, "players") == "2"
                    && l.contains(" softbox_px=")
            })
            .map(str::to_owned)
            .collect()
    };
    let start = Instant::now();
    while shot_lines(&desktop).len() < 3 {
        assert!(
            start.elapsed() < Duration::from_secs(90),
            "fewer than 3 screenshots of two players within 90 s\n{}",
            desktop.logs()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    host.wait_line("grab object=3", Duration::from_secs(30));
    // A few seconds more: throws seen, checksums confirmed on both sides.
    std::thread::sleep(Duration::from_secs(6));
    let lines = shot_lines(&desktop);
    let first = &lines[0];
    let rest = Rgb::load(Path::new(field(first, "path")));
    assert_eq!((rest.w, rest.h), (320, 240), "screenshot size");
    let bbox = px_box(field(first, "softbox_px"));
    let orange = rest
        .region(bbox, 0.0)
        .filter(|&(x, y)| is_orange(rest.at(x, y)))
        .count();
    let area = ((bbox[2] - bbox[0]) * (bbox[3] - bbox[1])).max(1.0);
    println!("box at {bbox:?}: {orange} orange pixels of {area:.0}");
    assert!(
        orange as f64 > 0.3 * area && orange > 200,
        "the soft box is not drawn where the rollback view projects it ({orange} orange \
         pixels in {area:.0})\n{first}"
    );
    // The throw moves the box: some later frame differs from the first over the box.
    let most = lines[1..]
        .iter()
        .map(|l| {
            let img = Rgb::load(Path::new(field(l, "path")));
            let (_, diff, _) = count_changed(&rest, &img, bbox, 4.0);
            diff
        })
        .max()
        .unwrap_or(0);
    println!(
        "{} frames of two players; the most changed over the box: {most} pixels",
        lines.len()
    );
    assert!(
        most > 300,
        "no frame shows the box moved by the bot's throw ({most} pixels changed)"
    );
    // The drawn world is the shared one: the desktop peer's confirmed frames agree with the
    // bot's, checksum for checksum.
    let (h, d) = (rollback_checks(&host), rollback_checks(&desktop));
    let common: Vec<_> = d.keys().filter(|k| h.contains_key(k)).collect();
    let differ: Vec<_> = common.iter().filter(|k| h[k] != d[k]).collect();
    println!(
        "checksums: {} common frames, {} differ (desktop {me})",
        common.len(),
        differ.len()
    );
    assert!(
        common.len() >= 5,
        "fewer than 5 common checked frames\n{}\n{}",
        desktop.logs(),
        host.logs()
    );
    assert!(differ.is_empty(), "checksums differ at {differ:?}");
    assert!(
        !desktop.stdout().contains("desync "),
        "a desync on the desktop peer\n{}",
        desktop.logs()
    );
    // A clean end with the summary and its corrections.
    send_signal("-TERM", &desktop);
    desktop.wait_exit(Duration::from_secs(20));
    let s = desktop.wait_line("rollback.summary", Duration::from_secs(1));
    println!("{s}");
    assert!(field(&s, "frames").parse::<u64>().unwrap() > 300, "{s}");
}
