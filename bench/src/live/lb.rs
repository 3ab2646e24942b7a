//! `softsync bench signal-lb`: many rooms through signaling behind a real load balancer.
//!
//! Starts three `softsync signal` instances and HAProxy with the repository's configuration
//! (`deploy/haproxy/signal.cfg`: the room's path hashed to one instance), then opens rooms
//! through the balancer: in each, a host and a joiner as light signaling clients
//! ([`SignalProbe`]: websockets only), and in a few, real peers on WebRTC. A joiner reached the
//! instance holding its room when its host hears it (`NewPeer`) and a signal it sends arrives.
//! Then one instance is SIGKILLed: its rooms' hosts register again through the balancer (as
//! real peers do by themselves), and every room — the moved ones, the others, the real ones —
//! must take a new joiner. Then the instance is started again (a restart after a crash): the
//! balancer must keep each room where its host is now, and every room takes one more joiner.
//! Rooms opened per second, join times, where the rooms were, how long the killed instance's
//! rooms were unjoinable.

use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use softsync_benchkit::{percentile, Csv, ResultLine};
use softsync_net_matchbox::{ProbeEvent, Role, SignalProbe};

use super::Proc;

/// What the bench is asked to do.
#[derive(Clone, Debug)]
pub struct LbPlan {
    /// Rooms of light clients.
    pub rooms: usize,
    /// Rooms of real peers (WebRTC) among them.
    pub real_rooms: usize,
    /// The HAProxy configuration.
    pub config: PathBuf,
    /// Rooms opened at once.
    pub parallel: usize,
}

const LB: &str = "127.0.0.1:3536";
const INSTANCES: [&str; 3] = ["127.0.0.1:3601", "127.0.0.1:3602", "127.0.0.1:3603"];
const STEP: Duration = Duration::from_secs(10);

/// What one light room's thread reports.
#[derive(Debug)]
enum RoomNews {
    /// The first joiner reached the host: ms from its connect to the host hearing it.
    Opened {
        join_ms: f64,
    },
    /// The joiner after the kill reached the host: ms from the kill.
    Rejoined {
        after_kill_ms: f64,
        moved: bool,
    },
    /// After the killed instance came back: a joiner reached the host again.
    AfterRestart {
        ms: f64,
    },
    Failed {
        room: usize,
        why: String,
    },
}

/// A host and a joiner meet through `lb`: the joiner sends its id as a signal; the host must
/// hear the joiner arrive and receive that signal. Returns the joiner's socket.
fn meet(host: &mut SignalProbe, room: &str) -> Result<SignalProbe, String> {
    let mut joiner = SignalProbe::connect(&format!("ws://{LB}"), room, Role::Join, STEP)
        .map_err(|e| e.to_string())?;
    let jid = joiner.id().to_owned();
    host.wait_for(STEP, |e| *e == ProbeEvent::NewPeer(jid.clone()))?
        .ok_or("the host never heard the joiner arrive")?;
    joiner.signal(host.id(), "\"hello\"")?;
    host.wait_for(
        STEP,
        |e| matches!(e, ProbeEvent::Signal { from, .. } if *from == jid),
    )?
    .ok_or("the joiner's signal never reached the host")?;
    Ok(joiner)
}

/// One light room: open it, hold it, after the kill register again if its socket died, and
/// take one more joiner.
fn light_room(k: usize, tx: mpsc::Sender<RoomNews>, killed: mpsc::Receiver<Instant>) {
    let room = format!("lb-room-{k}");
    let fail = |why: String| {
        let _ = tx.send(RoomNews::Failed { room: k, why });
    };
    let mut host = match SignalProbe::connect(&format!("ws://{LB}"), &room, Role::Host, STEP) {
        Ok(h) => h,
        Err(e) => return fail(format!("host: {e}")),
    };
    let t = Instant::now();
    let joiner = match meet(&mut host, &room) {
        Ok(j) => j,
        Err(e) => return fail(format!("first joiner: {e}")),
    };
    let _ = tx.send(RoomNews::Opened {
        join_ms: t.elapsed().as_secs_f64() * 1e3,
    });
    // hold the room until the kill; notice our socket dying
    let mut alive = true;
    let kill_at = loop {
        if let Ok(at) = killed.try_recv() {
            break at;
        }
        if alive && host.next_event(Duration::from_millis(100)).is_err() {
            alive = false;
        }
        if !alive {
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    drop(joiner);
    // after the kill: a host whose instance died registers again (as a member: the room is
    // empty on the instance that takes it over), retrying each 250 ms like a real peer's
    // transport retries its list
    let deadline = kill_at + Duration::from_secs(20);
    let mut moved = false;
    loop {
        if Instant::now() > deadline {
            return fail("no new joiner reached the host within 20 s of the kill".into());
        }
        if alive {
            // drain what the instance said; a closed socket means it was the killed one
            while let Ok(Some(_)) = host.next_event(Duration::from_millis(10)) {}
            if host.next_event(Duration::from_millis(10)).is_err() {
                alive = false;
            }
        }
        if !alive {
            match SignalProbe::connect(&format!("ws://{LB}"), &room, Role::Member, STEP) {
                Ok(h) => {
                    host = h;
                    alive = true;
                    moved = true;
                }
                Err(_) => {
                    std::thread::sleep(Duration::from_millis(250));
                    continue;
                }
            }
        }
        match meet(&mut host, &room) {
            Ok(_) => {
                let _ = tx.send(RoomNews::Rejoined {
                    after_kill_ms: kill_at.elapsed().as_secs_f64() * 1e3,
                    moved,
                });
                break;
            }
            Err(_) => std::thread::sleep(Duration::from_millis(250)),
        }
    }
    // the killed instance comes back: the room must stay where its host is now
    let restart_at = loop {
        if let Ok(at) = killed.try_recv() {
            break at;
        }
        if host.next_event(Duration::from_millis(100)).is_err() {
            return fail("the host's socket closed after the instance came back".into());
        }
    };
    let deadline = restart_at + Duration::from_secs(10);
    loop {
        match meet(&mut host, &room) {
            Ok(_) => {
                let _ = tx.send(RoomNews::AfterRestart {
                    ms: restart_at.elapsed().as_secs_f64() * 1e3,
                });
                return;
            }
            Err(e) if Instant::now() > deadline => {
                return fail(format!("no joiner reached the host after the restart: {e}"));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(250)),
        }
    }
}

fn wait_port(addr: &str, within: Duration) -> Result<(), String> {
    let a: SocketAddr = addr.parse().map_err(|_| format!("bad address {addr}"))?;
    let start = Instant::now();
    while TcpStream::connect_timeout(&a, Duration::from_millis(200)).is_err() {
        if start.elapsed() > within {
            return Err(format!("nothing listens on {addr} after {within:?}"));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

/// Which instance holds `room`: the one a direct join is let into (404 elsewhere).
fn holder(room: &str) -> Option<usize> {
    INSTANCES.iter().position(|i| {
        SignalProbe::connect(
            &format!("ws://{i}"),
            room,
            Role::Join,
            Duration::from_secs(2),
        )
        .map(SignalProbe::close)
        .is_ok()
    })
}

/// Run the bench; `Err` on a setup failure. Returns whether every room was opened and
/// joinable again after the kill.
pub fn signal_lb(out: &Path, plan: &LbPlan) -> Result<bool, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let dir = std::env::temp_dir().join(format!("softsync-lb-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let mut instances = Vec::new();
    for (k, addr) in INSTANCES.iter().enumerate() {
        let args = [
            "signal",
            "--bind",
            addr,
            // every connection comes from HAProxy's address
            "--max-per-source",
            "4096",
        ]
        .map(String::from);
        instances.push(Some(Proc::spawn(&dir, &format!("s{}", k + 1), &args)?));
    }
    let haproxy_log = std::fs::File::create(dir.join("haproxy.err")).map_err(|e| e.to_string())?;
    let mut haproxy = std::process::Command::new("haproxy")
        .args(["-f", &plan.config.display().to_string(), "-db"])
        .env("SOFTSYNC_LB_BIND", LB)
        .env("SOFTSYNC_SIGNAL_1", INSTANCES[0])
        .env("SOFTSYNC_SIGNAL_2", INSTANCES[1])
        .env("SOFTSYNC_SIGNAL_3", INSTANCES[2])
        .stdout(std::process::Stdio::null())
        .stderr(haproxy_log)
        .spawn()
        .map_err(|e| format!("cannot start haproxy (apt install haproxy): {e}"))?;
    let result = run(out, plan, &dir, &mut instances);
    let _ = haproxy.kill();
    let _ = haproxy.wait();
    drop(instances);
    if result.as_ref().is_ok_and(|ok| *ok) {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        println!("logs kept in {}", dir.display());
    }
    result
}

fn run(
    out: &Path,
    plan: &LbPlan,
    dir: &Path,
    instances: &mut [Option<Proc>],
) -> Result<bool, String> {
    for a in INSTANCES.iter().chain([&LB]) {
        wait_port(a, Duration::from_secs(20))?;
    }
    // HAProxy marks a server up after `rise` checks: wait until a room can be opened on each
    std::thread::sleep(Duration::from_millis(1500));

    // --- open the light rooms, `parallel` at a time ---
    let (tx, rx) = mpsc::channel();
    let mut kill_txs = Vec::new();
    let mut threads = Vec::new();
    let start = Instant::now();
    let mut opened = Vec::new();
    let mut failures: Vec<String> = Vec::new();
    for k in 0..plan.rooms {
        let (ktx, krx) = mpsc::channel();
        kill_txs.push(ktx);
        let tx = tx.clone();
        threads.push(
            std::thread::Builder::new()
                .stack_size(256 * 1024)
                .spawn(move || light_room(k, tx, krx))
                .map_err(|e| e.to_string())?,
        );
        // keep at most `parallel` rooms opening
        while threads.len() - opened.len() - failures.len() >= plan.parallel {
            match rx.recv_timeout(Duration::from_secs(30)) {
                Ok(RoomNews::Opened { join_ms, .. }) => opened.push(join_ms),
                Ok(RoomNews::Failed { room, why }) => failures.push(format!("room {room}: {why}")),
                Ok(_) => {}
                Err(_) => return Err("rooms stopped opening".into()),
            }
        }
    }
    while opened.len() + failures.len() < plan.rooms {
        match rx.recv_timeout(Duration::from_secs(30)) {
            Ok(RoomNews::Opened { join_ms, .. }) => opened.push(join_ms),
            Ok(RoomNews::Failed { room, why }) => failures.push(format!("room {room}: {why}")),
            Ok(_) => {}
            Err(_) => return Err("rooms stopped opening".into()),
        }
    }
    let open_s = start.elapsed().as_secs_f64();
    let per_s = opened.len() as f64 / open_s;
    // where the rooms are
    let mut per_instance = [0usize; 3];
    let mut on_first = Vec::new();
    for k in 0..plan.rooms {
        if let Some(i) = holder(&format!("lb-room-{k}")) {
            per_instance[i] += 1;
            if i == 0 {
                on_first.push(k);
            }
        }
    }

    // --- a few real rooms (WebRTC) through the balancer ---
    let url = format!("ws://{LB}");
    let mut real = Vec::new();
    for r in 0..plan.real_rooms {
        let room = format!("lb-real-{r}");
        let d = ["--duration", "120"];
        let host = Proc::peer(dir, &format!("{room}-host"), "host", &room, &url, &d)?;
        host.line("hosting", Duration::from_secs(30))?;
        let bot = Proc::peer(dir, &format!("{room}-b1"), "join", &room, &url, &d)?;
        bot.line("joined", Duration::from_secs(30))?;
        real.push((room, host, bot));
    }
    let real_holders: Vec<Option<usize>> = real.iter().map(|(r, _, _)| holder(r)).collect();

    // --- kill the first instance ---
    let kill_at = Instant::now();
    if let Some(mut p) = instances[0].take() {
        let _ = p.child.kill();
        let _ = p.child.wait();
    }
    for k in &kill_txs {
        let _ = k.send(kill_at);
    }
    // every room that opened says once more: joinable again, or not
    let mut rejoined = Vec::new();
    let (mut moved_ms, mut others_ms) = (Vec::new(), Vec::new());
    let mut answered = 0;
    while answered < opened.len() {
        match rx.recv_timeout(Duration::from_secs(40)) {
            Ok(RoomNews::Rejoined {
                after_kill_ms,
                moved,
            }) => {
                rejoined.push(after_kill_ms);
                if moved { &mut moved_ms } else { &mut others_ms }.push(after_kill_ms);
            }
            Ok(RoomNews::Failed { room, why }) => failures.push(format!("room {room}: {why}")),
            Ok(RoomNews::Opened { .. } | RoomNews::AfterRestart { .. }) => continue,
            Err(_) => {
                failures.push("rooms stopped answering after the kill".into());
                break;
            }
        }
        answered += 1;
    }
    // --- the killed instance comes back (a restart after a crash) ---
    instances[0] = Some(Proc::spawn(
        dir,
        "s1-again",
        &["signal", "--bind", INSTANCES[0], "--max-per-source", "4096"].map(String::from),
    )?);
    wait_port(INSTANCES[0], Duration::from_secs(20))?;
    // HAProxy takes it back after `rise` checks (4 × 250 ms)
    std::thread::sleep(Duration::from_millis(2000));
    let restart_at = Instant::now();
    for k in &kill_txs {
        let _ = k.send(restart_at);
    }
    let mut after_restart = Vec::new();
    let mut answered = 0;
    while answered < rejoined.len() {
        match rx.recv_timeout(Duration::from_secs(30)) {
            Ok(RoomNews::AfterRestart { ms }) => after_restart.push(ms),
            Ok(RoomNews::Failed { room, why }) => failures.push(format!("room {room}: {why}")),
            Ok(_) => continue,
            Err(_) => {
                failures.push("rooms stopped answering after the restart".into());
                break;
            }
        }
        answered += 1;
    }
    // real rooms: a new peer joins each, through the balancer, after the kill and restart
    let mut real_rejoined = 0;
    for (room, _, _) in &real {
        let d = ["--duration", "60"];
        let late = Proc::peer(dir, &format!("{room}-late"), "join", room, &url, &d)?;
        match late.line("joined", Duration::from_secs(30)) {
            Ok(_) => real_rejoined += 1,
            Err(e) => failures.push(format!("{room}: late joiner: {e}")),
        }
    }
    for t in threads {
        let _ = t.join();
    }
    for f in failures.iter().take(10) {
        println!("FAILED {f}");
    }
    let p = |v: &[f64], q: f64| {
        if v.is_empty() {
            f64::NAN
        } else {
            percentile(v, q)
        }
    };
    let mut csv = Csv::new(&["phase", "ms"]);
    for x in &opened {
        csv.row(["join".to_string(), format!("{x:.1}")]);
    }
    for x in &rejoined {
        csv.row(["after_kill".to_string(), format!("{x:.1}")]);
    }
    for x in &after_restart {
        csv.row(["after_restart".to_string(), format!("{x:.1}")]);
    }
    csv.write(out.join("signal_lb.csv"))
        .map_err(|e| e.to_string())?;
    let ok = failures.is_empty()
        && opened.len() == plan.rooms
        && rejoined.len() == plan.rooms
        && after_restart.len() == plan.rooms
        && real_rejoined == plan.real_rooms;
    let lines = [
        ResultLine::new("lb.rooms")
            .field("rooms", plan.rooms)
            .field("instances", INSTANCES.len())
            .field("opened", opened.len())
            .fixed("opened_per_s", per_s, 1)
            .fixed("join_p50_ms", p(&opened, 0.5), 1)
            .fixed("join_p95_ms", p(&opened, 0.95), 1)
            .fixed("join_max_ms", opened.iter().copied().fold(0.0, f64::max), 1)
            .field(
                "per_instance",
                format!(
                    "{}/{}/{}",
                    per_instance[0], per_instance[1], per_instance[2]
                ),
            ),
        ResultLine::new("lb.kill")
            .field("rooms_on_killed", on_first.len())
            .field("moved", moved_ms.len())
            .field("joinable_after", rejoined.len())
            .fixed("moved_p50_ms", p(&moved_ms, 0.5), 0)
            .fixed(
                "moved_max_ms",
                moved_ms.iter().copied().fold(0.0, f64::max),
                0,
            )
            .fixed(
                "others_max_ms",
                others_ms.iter().copied().fold(0.0, f64::max),
                0,
            ),
        ResultLine::new("lb.restart")
            .field("joinable_after", after_restart.len())
            .fixed(
                "max_ms",
                after_restart.iter().copied().fold(0.0, f64::max),
                0,
            ),
        ResultLine::new("lb.real")
            .field("rooms", plan.real_rooms)
            .field(
                "on_killed",
                real_holders.iter().filter(|h| **h == Some(0)).count(),
            )
            .field("joined_after_kill", real_rejoined),
        ResultLine::new("lb.summary")
            .field("failures", failures.len())
            .field("ok", ok),
    ];
    let mut md = String::from(
        "# Signaling behind a load balancer\n\nGenerated by `scripts/bench-signal-lb` (= `softsync bench signal-lb` in a network namespace): three `softsync signal` instances behind HAProxy (`deploy/haproxy/signal.cfg`: the room's path picks an instance on a consistent-hash ring, a stick table keeps it there), rooms of a host and a joiner as light signaling clients plus a few rooms of real peers; then one instance is SIGKILLed and every room must take a new joiner; then it is started again and every room must take one more.\n\n```\n",
    );
    for l in &lines {
        println!("{l}");
        md.push_str(&format!("{l}\n"));
    }
    md.push_str("```\n");
    std::fs::write(out.join("signal_lb.md"), md).map_err(|e| e.to_string())?;
    Ok(ok)
}
