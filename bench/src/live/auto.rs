//! `softsync bench auto`: the thesis room with `method: auto` against the same room with every
//! soft body at its finest level (and at its 1× level, the plain thesis room's settings), one
//! peer in-process, the same bot script in each run: reach, grab, squeeze and let go of each
//! soft body in turn, with rests between. Per run the step cost (median and p95 of
//! `Peer::fixed_step`'s wall time); per soft body the error of the auto run (and of the 1×
//! run) against the finest run, frame by frame: the RMS and largest distance of its surface's
//! vertices (the same mesh, so the same vertices, at every level) after the rigid fit that
//! best maps one on the other — the *shape* error; where the body is differs as soon as two
//! runs' grabs land on different particles and a body rolls or slides differently, so that
//! (the pose error) is written to the CSV but is not the figure — and how long each body spent
//! at each level.
//!
//! Writes `auto.csv` (per object), `auto_frames.csv` (per frame) and `auto.svg` (step cost
//! over time), and prints `RESULT framework.auto frame_ms=… fixed_frame_ms=…
//! worst_error_mm=…`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant as Wall;

use softsync_benchkit::plotters::style::RGBColor;
use softsync_benchkit::{
    median, percentile, write_svg, ChartStyle, Csv, LineChart, Progress, ResultLine, Series,
};
use softsync_net::{Instant, NetId, PeerId, SendPolicy, Session};
use softsync_peer::bot::{parse, Bot};
use softsync_peer::mirror::LocalBody;
use softsync_peer::{BodyClass, Peer, PeerConfig, Scene};
use softsync_softbody::metrics::rigid_fit_error;

const DT: f32 = 1.0 / 90.0;

/// Each soft body in turn: reach, grab, squeeze 2.5 cm, hold, let go, lift away; then rest.
const SCRIPT: &str = "
wait 1.5
reach right softball in 0.6; grab right; squeeze right 0.025 in 0.4; wait 1; release right
offset right 0 0.15 0 in 0.4; wait 1.5
reach right bunny in 0.6; grab right; squeeze right 0.025 in 0.4; wait 1; release right
offset right 0 0.15 0 in 0.4; wait 1.5
reach right softbox in 0.6; grab right; squeeze right 0.025 in 0.4; wait 1; release right
offset right 0 0.15 0 in 0.4; wait 3
";

/// One soft object in one frame: its id, its level, its surface's vertices.
type SoftFrame = (NetId, Option<u8>, Vec<glam::Vec3>);

/// One run: step costs and, per soft object per frame, its vertices.
struct Run {
    step_ms: Vec<f64>,
    /// Per frame: (object, level, vertices).
    frames: Vec<Vec<SoftFrame>>,
    particles: Vec<usize>,
    /// The soft objects' class names.
    classes: BTreeMap<NetId, String>,
}

/// How the soft classes run.
#[derive(Clone, Copy, PartialEq)]
enum Mode {
    Auto,
    /// Every auto class at ladder level `usize::MAX` = finest, or at its spawn (1×) level.
    Finest,
    Base,
}

fn scene_for(auto: &Scene, mode: Mode) -> Scene {
    let mut s = auto.clone();
    if mode == Mode::Auto {
        return s;
    }
    for c in &mut s.classes {
        if let Some(a) = c.auto.take() {
            let level = match mode {
                Mode::Finest => a.ladder.configs.len() - 1,
                _ => a.base,
            };
            c.body = BodyClass::Soft(Box::new(a.ladder.configs[level].clone()));
        }
    }
    s
}

fn run(scene: Scene, seconds: f64, progress: &Progress) -> Result<Run, String> {
    let me = PeerId(1);
    let policy = SendPolicy::default();
    let cfg = scene.session_config(policy.clone(), policy.clone(), policy);
    let session = Session::host(me, cfg, Instant::ZERO);
    let config = PeerConfig {
        dt_s: DT,
        avatar: true,
        ..PeerConfig::default()
    };
    let mut peer =
        Peer::new(Instant::ZERO, session, None, scene, config).map_err(|e| e.to_string())?;
    peer.open(Instant::ZERO).map_err(|e| e.to_string())?;
    let mut bot = Bot::new(parse(SCRIPT).map_err(|e| e.to_string())?);
    bot.check(peer.scene())?;
    let frames = (seconds / f64::from(DT)) as usize;
    let mut out = Run {
        step_ms: Vec::with_capacity(frames),
        frames: Vec::with_capacity(frames),
        particles: Vec::new(),
        classes: BTreeMap::new(),
    };
    for k in 0..frames {
        let now = Instant::from_micros((k as f64 * f64::from(DT) * 1e6) as u64);
        peer.pump(now).map_err(|e| e.to_string())?;
        bot.step(now, &mut peer, None);
        let t0 = Wall::now();
        peer.fixed_step(now);
        out.step_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        while peer.poll_transmit(now).is_some() {}
        while peer.poll_event().is_some() {}
        while bot.poll_message().is_some() {}
        let mut soft = Vec::new();
        let mut particles = 0;
        for (id, o) in peer.objects() {
            if let LocalBody::Soft(h) = o.body {
                if let Some(b) = peer.soft_bodies().get(h) {
                    particles += b.num_particles();
                    soft.push((*id, o.level, b.vertices().to_vec()));
                }
            }
        }
        out.particles.push(particles);
        out.frames.push(soft);
        progress.inc();
    }
    for (id, o) in peer.objects() {
        if matches!(o.body, LocalBody::Soft(_)) {
            out.classes
                .insert(*id, peer.scene().name_of(o.kind).to_owned());
        }
    }
    Ok(out)
}

/// One object's error against the finest run, mm.
#[derive(Clone, Copy, Debug, Default)]
struct Err {
    /// Worst RMS of the surface's shape (after the rigid fit that best maps one on the other).
    shape_rms: f64,
    /// Largest vertex distance after that fit.
    shape_max: f64,
    /// Worst RMS without the fit: where the two runs' bodies are (the runs' manipulations
    /// diverge chaotically once a body rolls or slides differently).
    pose_rms: f64,
}

/// Run `a`'s error against the finest run: per object, and per frame the worst shape RMS.
fn errors(a: &Run, finest: &Run) -> (BTreeMap<NetId, Err>, Vec<f64>) {
    let mut per: BTreeMap<NetId, Err> = BTreeMap::new();
    let mut per_frame = Vec::new();
    for (fa, ff) in a.frames.iter().zip(&finest.frames) {
        let mut worst = 0.0f64;
        for (id, _, va) in fa {
            let Some((_, _, vf)) = ff.iter().find(|(i, _, _)| i == id) else {
                continue;
            };
            if va.len() != vf.len() || va.is_empty() {
                continue;
            }
            let (rms, max) = rigid_fit_error(va, vf, glam::Quat::IDENTITY);
            let pose = (va
                .iter()
                .zip(vf)
                .map(|(x, y)| f64::from(x.distance_squared(*y)))
                .sum::<f64>()
                / va.len() as f64)
                .sqrt();
            let e = per.entry(*id).or_default();
            e.shape_rms = e.shape_rms.max(f64::from(rms) * 1e3);
            e.shape_max = e.shape_max.max(f64::from(max) * 1e3);
            e.pose_rms = e.pose_rms.max(pose * 1e3);
            worst = worst.max(f64::from(rms) * 1e3);
        }
        per_frame.push(worst);
    }
    (per, per_frame)
}

/// Seconds at each level per object in the auto run: "level:seconds" pairs.
fn time_at_levels(run: &Run, id: NetId) -> String {
    let mut at: std::collections::BTreeMap<String, f64> = Default::default();
    for f in &run.frames {
        if let Some((_, level, _)) = f.iter().find(|(i, _, _)| *i == id) {
            let key = level.map_or("spawn".to_owned(), |l| l.to_string());
            *at.entry(key).or_default() += f64::from(DT);
        }
    }
    at.iter()
        .map(|(l, s)| format!("{l}:{s:.1}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `softsync bench auto`.
pub fn auto(out: &Path, seconds: f64, assets: &Path) -> Result<(), String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut scene = Scene::by_name("thesis-room-auto", assets)?;
    scene.probe_auto(|| crate::wall_s() * 1e3)?;
    let mut ladders = Csv::new(&[
        "class",
        "level",
        "resolution",
        "particles",
        "probe_step_ms",
        "probe_error_mm",
        "touch",
        "squeeze",
    ]);
    for (_, c) in scene.object_classes() {
        let Some(a) = &c.auto else { continue };
        for (l, cand) in a.ladder.probed.iter().enumerate() {
            ladders.row([
                c.name.clone(),
                l.to_string(),
                format!("{}", a.ladder.resolutions[l]),
                a.ladder.particles[l].to_string(),
                format!("{:.4}", cand.cost_ms),
                format!("{:.2}", cand.error_mm),
                (l == a.ladder.touch).to_string(),
                (l == a.ladder.squeeze).to_string(),
            ]);
        }
    }
    ladders
        .write(out.join("auto_ladders.csv"))
        .map_err(|e| e.to_string())?;
    let frames = (seconds / f64::from(DT)) as u64;
    let progress = Progress::new(frames * 3, "bench auto");
    let auto_run = run(scene_for(&scene, Mode::Auto), seconds, &progress)?;
    let finest = run(scene_for(&scene, Mode::Finest), seconds, &progress)?;
    let base = run(scene_for(&scene, Mode::Base), seconds, &progress)?;
    progress.finish();
    let med = |r: &Run| median(&r.step_ms);
    let p95 = |r: &Run| percentile(&r.step_ms, 0.95);
    let (per_object, per_frame) = errors(&auto_run, &finest);
    let (per_base, _) = errors(&base, &finest);
    let worst = per_object.values().map(|o| o.shape_rms).fold(0.0, f64::max);
    let worst_max = per_object.values().map(|o| o.shape_max).fold(0.0, f64::max);
    let base_worst = per_base.values().map(|o| o.shape_rms).fold(0.0, f64::max);
    // per object table
    let mut csv = Csv::new(&[
        "object",
        "class",
        "shape_rms_mm",
        "shape_max_mm",
        "pose_rms_mm",
        "base_shape_rms_mm",
        "seconds_at_level",
    ]);
    let mut names = String::new();
    for (id, e) in &per_object {
        let class = auto_run.classes.get(id).cloned().unwrap_or_default();
        let b = per_base.get(id).copied().unwrap_or_default();
        csv.row([
            id.0.to_string(),
            class.clone(),
            format!("{:.2}", e.shape_rms),
            format!("{:.2}", e.shape_max),
            format!("{:.2}", e.pose_rms),
            format!("{:.2}", b.shape_rms),
            time_at_levels(&auto_run, *id),
        ]);
        let _ = write!(names, "{class}:{:.2},", e.shape_rms);
    }
    csv.write(out.join("auto.csv")).map_err(|e| e.to_string())?;
    let mut frames_csv = Csv::new(&[
        "t_s",
        "auto_ms",
        "finest_ms",
        "base_ms",
        "auto_particles",
        "finest_particles",
        "error_rms_mm",
    ]);
    for k in 0..auto_run.step_ms.len() {
        frames_csv.row([
            format!("{:.3}", k as f64 * f64::from(DT)),
            format!("{:.4}", auto_run.step_ms[k]),
            format!("{:.4}", finest.step_ms.get(k).copied().unwrap_or(f64::NAN)),
            format!("{:.4}", base.step_ms.get(k).copied().unwrap_or(f64::NAN)),
            auto_run.particles[k].to_string(),
            finest.particles.get(k).copied().unwrap_or(0).to_string(),
            format!("{:.3}", per_frame.get(k).copied().unwrap_or(f64::NAN)),
        ]);
    }
    frames_csv
        .write(out.join("auto_frames.csv"))
        .map_err(|e| e.to_string())?;
    chart(out, &auto_run, &finest, &base).map_err(|e| e.to_string())?;
    println!(
        "{}",
        ResultLine::new("framework.auto")
            .fixed("frame_ms", med(&auto_run), 3)
            .fixed("fixed_frame_ms", med(&finest), 3)
            .fixed("base_frame_ms", med(&base), 3)
            .fixed("frame_p95_ms", p95(&auto_run), 3)
            .fixed("fixed_frame_p95_ms", p95(&finest), 3)
            .fixed("speedup", med(&finest) / med(&auto_run).max(1e-9), 2)
            .fixed("worst_error_mm", worst, 2)
            .fixed("worst_vertex_mm", worst_max, 2)
            .fixed("base_worst_error_mm", base_worst, 2)
            .field("per_object_rms_mm", names.trim_end_matches(','))
            .field("seconds", seconds)
    );
    Ok(())
}

fn chart(
    out: &Path,
    auto: &Run,
    finest: &Run,
    base: &Run,
) -> Result<(), Box<dyn std::error::Error>> {
    // a 0.25 s running median, so the chart shows the cost of each phase, not each step
    let smooth = |v: &[f64]| -> Vec<(f64, f64)> {
        let w = (0.25 / f64::from(DT)) as usize;
        (0..v.len())
            .step_by(w.max(1) / 2)
            .map(|k| {
                let lo = k.saturating_sub(w / 2);
                let hi = (k + w / 2).min(v.len());
                (k as f64 * f64::from(DT), median(&v[lo..hi]))
            })
            .collect()
    };
    let top = [auto, finest, base]
        .iter()
        .flat_map(|r| smooth(&r.step_ms))
        .map(|p| p.1)
        .fold(0.0, f64::max);
    let series = vec![
        Series::new("auto", RGBColor(200, 40, 40), smooth(&auto.step_ms)),
        Series::new(
            "finest level",
            RGBColor(40, 80, 200),
            smooth(&finest.step_ms),
        ),
        Series::new(
            "1x level (the thesis room's)",
            RGBColor(120, 120, 120),
            smooth(&base.step_ms),
        ),
    ];
    let secs = auto.step_ms.len() as f64 * f64::from(DT);
    let c = LineChart {
        title: "Thesis room step cost: method auto vs fixed resolutions".into(),
        x_desc: "time (s): grab and squeeze softball, bunny, softbox in turn".into(),
        y_desc: "step ms (0.25 s running median)".into(),
        x_range: 0.0..secs,
        x_log: false,
        y_range: 0.0..top * 1.15,
        series,
        style: ChartStyle::FIGURE,
    };
    write_svg(out.join("auto.svg"), (900, 500), &[c])?;
    Ok(())
}
