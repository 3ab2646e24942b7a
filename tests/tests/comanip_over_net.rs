//! Several hands from several peers on one soft body (issue 31, co-manipulation), in-process
//! on virtual time with the peer library the app runs: a host that owns the `bench-ball`
//! room's soft ball and two clients, on net's in-memory hub behind the seeded link
//! conditioner (20 ms, 5 ms jitter, 2 % loss unless said). The host's own hand and the
//! clients' remote hands hold three particles of the ball at once and pull it apart; nobody's
//! grab is refused, authority never moves, every peer agrees on who holds what and, at rest
//! again, on the shape. Then: a remote hand at 5 % loss, a holder's peer that dies, `Locked`
//! and `OwnerMustAgree`, and hostile remote hands.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

mod common;

use std::time::Duration;

use common::hub::{Node, DT, HOST};
use glam::{Quat, Vec3};
use softsync_interaction::{HandConfig, HandInput, HandSample};
use softsync_net::{AuthorityPolicy, Delivery, Instant, MemoryHub, MessageTarget, NetId, PeerId};
use softsync_peer::messages::RemoteHand;
use softsync_peer::{Event, PeerConfig, Scene};

const A: PeerId = PeerId(101);
const B: PeerId = PeerId(102);

fn scene(policy: AuthorityPolicy) -> Scene {
    let mut scene = Scene::by_name("bench-ball", &common::repo_file("assets")).unwrap();
    let k = scene.kind("softball").unwrap();
    scene.classes[usize::from(k.0)].authority = policy;
    scene
}

fn node(hub: &MemoryHub, me: PeerId, seed: u64, scene: Scene, loss: f64, agree: bool) -> Node {
    let config = PeerConfig {
        hand: HandConfig {
            physical_controller: false,
            hover_radius_m: 0.015,
            ..HandConfig::default()
        },
        dt_s: DT,
        agree_to_hands: agree,
        ..PeerConfig::default()
    };
    Node::with_loss(hub, me, seed, scene, config, loss)
}

fn input(now: Instant, at: Vec3, grip: f32) -> HandInput {
    HandInput {
        sample: HandSample {
            position_m: at,
            rotation: Quat::IDENTITY,
            time_s: now.as_secs_f64(),
        },
        grip,
        trigger: 0.0,
    }
}

/// A hand's plan: grab particle `particle` at `grab_s`, move by `pull` over `pull_s` from
/// `pull_at_s`, let go at `release_s`.
#[derive(Clone, Copy)]
struct Plan {
    particle: usize,
    start: Vec3,
    grab_s: f32,
    pull: Vec3,
    pull_at_s: f32,
    pull_s: f32,
    release_s: f32,
}

/// A hand's plan (see [`Plan`]), its fields in order.
fn plan(
    particle: usize,
    start: Vec3,
    grab_s: f32,
    pull: Vec3,
    pull_at_s: f32,
    pull_s: f32,
    release_s: f32,
) -> Plan {
    Plan {
        particle,
        start,
        grab_s,
        pull,
        pull_at_s,
        pull_s,
        release_s,
    }
}

impl Plan {
    fn hand(&self, now: Instant, t: f32) -> Option<HandInput> {
        if t < self.grab_s - 0.1 {
            return None;
        }
        let k = ((t - self.pull_at_s) / self.pull_s).clamp(0.0, 1.0);
        let grip = if t >= self.grab_s && t < self.release_s {
            1.0
        } else {
            0.0
        };
        Some(input(now, self.start + self.pull * k, grip))
    }

    fn goal(&self, t: f32) -> Vec3 {
        self.start + self.pull * ((t - self.pull_at_s) / self.pull_s).clamp(0.0, 1.0)
    }
}

struct Room {
    nodes: Vec<Node>,
    now: Instant,
    /// Virtual seconds since the room opened.
    t: f32,
    ball: NetId,
}

impl Room {
    fn new(policy: AuthorityPolicy, loss: f64, host_agrees: bool) -> (Room, MemoryHub) {
        let hub = MemoryHub::new(1200);
        let nodes = vec![
            node(&hub, HOST, 3, scene(policy), loss, host_agrees),
            node(&hub, A, 4, scene(policy), loss, true),
            node(&hub, B, 5, scene(policy), loss, true),
        ];
        let mut room = Room {
            nodes,
            now: Instant::ZERO,
            t: 0.0,
            ball: NetId(0),
        };
        // everyone joins; the ball falls onto the table and settles
        room.run(2.0, &mut |_, _, _| None);
        for n in &room.nodes {
            assert!(n.peer.joined(), "{:?} never joined", n.peer.me());
            assert!(n.warnings.is_empty(), "{:?}", n.warnings);
        }
        room.ball = room.nodes[0].id_of("softball")[0];
        (room, hub)
    }

    /// Run for `secs`, each node's right hand given by `hand(node, now, t)`.
    fn run(&mut self, secs: f32, hand: &mut dyn FnMut(usize, Instant, f32) -> Option<HandInput>) {
        let end = self.t + secs;
        while self.t < end {
            self.now += Duration::from_secs_f32(DT);
            self.t += DT;
            for (i, n) in self.nodes.iter_mut().enumerate() {
                if n.link_dead {
                    continue;
                }
                let h = hand(i, self.now, self.t);
                n.frame_input(self.now, h);
                assert!(n.warnings.is_empty(), "node {i}: {:?}", n.warnings);
            }
        }
    }

    fn particles(&mut self, i: usize) -> Vec<Vec3> {
        let (now, ball) = (self.now, self.ball);
        self.nodes[i].peer.shown_state(now, ball).unwrap().particles
    }

    /// What node `i` draws: the replicated state with its own remote hands' corrections.
    fn drawn(&self, i: usize) -> Vec<Vec3> {
        self.nodes[i].peer.local_state(self.ball).unwrap().particles
    }

    fn holders(&self, i: usize) -> Vec<(PeerId, u8, u32)> {
        self.nodes[i]
            .peer
            .holders(self.ball)
            .iter()
            .map(|h| (h.peer, h.hand, h.particle))
            .collect()
    }
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

fn p95(mut v: Vec<f32>) -> f32 {
    v.sort_by(f32::total_cmp);
    v.get((v.len() * 95 / 100).min(v.len().saturating_sub(1)))
        .copied()
        .unwrap_or(0.0)
}

/// Three particles far apart: the leftmost, the rightmost and the topmost.
fn three(p: &[Vec3]) -> [usize; 3] {
    let by = |f: &dyn Fn(&Vec3) -> f32| {
        (0..p.len())
            .max_by(|a, b| f(&p[*a]).total_cmp(&f(&p[*b])))
            .unwrap()
    };
    [by(&|v| -v.x), by(&|v| v.x), by(&|v| v.y)]
}

#[test]
fn two_remote_hands_and_the_owners_own_hand_pull_one_body_apart_and_every_peer_agrees() {
    let (mut room, _hub) = Room::new(AuthorityPolicy::Free, 0.02, true);
    let rest = room.particles(0);
    let [left, right, top] = three(&rest);
    let t0 = room.t;
    // the host (owner) holds the left side; A the right, B the top, a moment later
    let plans = [
        plan(
            left,
            rest[left],
            t0 + 0.2,
            Vec3::new(-0.06, 0.0, 0.0),
            t0 + 0.8,
            0.5,
            t0 + 3.0,
        ),
        plan(
            right,
            room.particles(1)[right],
            t0 + 0.4,
            Vec3::new(0.06, 0.0, 0.0),
            t0 + 0.8,
            0.5,
            t0 + 3.0,
        ),
        plan(
            top,
            room.particles(2)[top],
            t0 + 0.42,
            Vec3::new(0.0, 0.04, 0.0),
            t0 + 0.8,
            0.5,
            t0 + 3.0,
        ),
    ];
    let mut gaps: Vec<f32> = Vec::new();
    let mut uncorrected: Vec<f32> = Vec::new();
    // max over particles of the distance to the owner's body at the same instant: drawn
    // (with the correction), replicated alone
    let mut shape_err: [Vec<f32>; 2] = [Vec::new(), Vec::new()];
    let mut owner_gaps = [0.0f32; 3];
    let mut holders_agreed_at: Option<f32> = None;
    let mut stretch = 0.0f32;
    let ball = room.ball;
    let mut t = room.t;
    while t < t0 + 3.0 {
        room.run(DT, &mut |i, now, t| plans[i].hand(now, t));
        t = room.t;
        if t > t0 + 1.0 {
            // each client's hand against its particle as that client shows it
            let truth = room.particles(0);
            for i in 1..3 {
                // the whole body against the owner's now: the correction's error elsewhere
                let (d, r) = (room.drawn(i), room.particles(i));
                shape_err[0].push(max_distance(&d, &truth));
                shape_err[1].push(max_distance(&r, &truth));
                let p = room.drawn(i)[plans[i].particle];
                gaps.push(p.distance(plans[i].goal(t)));
                let p = room.particles(i)[plans[i].particle];
                uncorrected.push(p.distance(plans[i].goal(t)));
            }
        }
        if t > t0 + 2.3 && t < t0 + 2.9 {
            // the owner's body: each hand's particle at its hand
            let owner = room.particles(0);
            for (k, plan) in plans.iter().enumerate() {
                let d = owner[plan.particle].distance(plan.goal(t));
                owner_gaps[k] = owner_gaps[k].max(d);
            }
            stretch = stretch.max(owner[right].x - owner[left].x - (rest[right].x - rest[left].x));
        }
        if holders_agreed_at.is_none() {
            let h = room.holders(0);
            if h.len() == 3 && (1..3).all(|i| room.holders(i) == h) {
                holders_agreed_at = Some(t - t0);
            }
        }
    }
    let agreed = holders_agreed_at.expect("the peers never agreed on three holders");
    assert!(agreed < 1.0, "holders agreed only after {agreed} s");
    let expect = vec![
        (HOST, 1, left as u32),
        (A, 1, right as u32),
        (B, 1, top as u32),
    ];
    assert_eq!(room.holders(1), expect);
    // each hand moved its particle on the owner's body, and the body stretched between them
    eprintln!("owner's particle-to-hand distance, max while holding still: {owner_gaps:?} m");
    for (k, g) in owner_gaps.iter().enumerate() {
        assert!(
            *g < 0.002,
            "hand {k}'s particle is {g} m from it on the owner"
        );
    }
    assert!(stretch > 0.09, "the ball stretched only {stretch} m");
    // what each client shows of its own hand: the local correction keeps it at the hand
    let (gap, without) = (p95(gaps), p95(uncorrected));
    eprintln!("own-hand gap p95 {gap} m drawn, {without} m replicated alone");
    let [drawn_err, replicated_err] = shape_err.map(p95);
    eprintln!(
        "shape vs the owner's now, p95 of the worst particle: {drawn_err} m drawn, \
         {replicated_err} m replicated alone"
    );
    assert!(
        drawn_err < replicated_err + 0.001,
        "the correction made the shape worse"
    );
    assert!(gap < 0.003, "own-hand gap p95 {gap} m");
    assert!(
        without > 0.008,
        "the replicated shape alone lags only {without} m"
    );
    // nobody's grab was refused and authority never moved
    for n in &room.nodes {
        assert!(n
            .first(|e| matches!(e, Event::AuthorityDenied(_)))
            .is_none());
        assert!(n
            .first(|e| matches!(e, Event::AuthorityGained(_)))
            .is_none());
        assert_eq!(n.peer.session().owner(ball), Some(HOST));
    }
    assert_eq!(room.nodes[0].peer.counters().remote_hands_taken, 2);
    for i in 1..3 {
        assert_eq!(room.nodes[i].peer.counters().remote_grabs, 1);
    }
    // all let go; the ball comes to rest and every peer shows it the same
    room.run(4.0, &mut |i, now, t| plans[i].hand(now, t));
    assert_eq!(room.nodes[0].peer.remote_hands_applied(), 0);
    for i in 0..3 {
        assert!(
            room.holders(i).is_empty(),
            "node {i}: {:?}",
            room.holders(i)
        );
    }
    let host = room.particles(0);
    for i in 1..3 {
        let apart = max_distance(&host, &room.particles(i));
        assert!(
            apart < 0.005,
            "node {i} shows the ball {apart} m off the host"
        );
    }
    assert_eq!(room.nodes[0].peer.counters().remote_hands_expired, 0);
}

#[test]
fn a_remote_hand_at_5_percent_loss_pulls_the_owners_body_and_lets_go_with_a_throw() {
    let (mut room, _hub) = Room::new(AuthorityPolicy::Free, 0.05, true);
    let rest = room.particles(0);
    let [left, right, _] = three(&rest);
    let t0 = room.t;
    let hold = plan(left, rest[left], t0 + 0.2, Vec3::ZERO, t0, 1.0, t0 + 5.0);
    let pull = plan(
        right,
        room.particles(1)[right],
        t0 + 0.5,
        Vec3::new(0.05, 0.02, 0.0),
        t0 + 0.8,
        0.8,
        t0 + 2.2,
    );
    let mut seen = 0.0f32;
    let mut t = room.t;
    while t < t0 + 2.2 {
        room.run(DT, &mut |i, now, t| match i {
            0 => hold.hand(now, t),
            1 => pull.hand(now, t),
            _ => None,
        });
        t = room.t;
        // B, which holds nothing, sees the pull through replication alone
        let p = room.particles(2)[right];
        seen = seen.max(p.x - rest[right].x);
    }
    let owner = room.particles(0)[right];
    let d = owner.distance(pull.goal(t));
    assert!(
        d < 0.012,
        "the owner's particle is {d} m from the remote hand"
    );
    assert!(seen > 0.03, "a third peer saw the pull only {seen} m");
    let host = room.nodes[0].peer.counters();
    assert_eq!(host.remote_hands_taken, 1);
    assert_eq!(host.remote_hands_expired, 0);
    // the release reaches the owner (sent three times) and the holders say so
    room.run(0.5, &mut |i, now, t| match i {
        0 => hold.hand(now, t),
        1 => pull.hand(now, t),
        _ => None,
    });
    assert_eq!(room.nodes[0].peer.remote_hands_applied(), 0);
    assert_eq!(room.holders(2), vec![(HOST, 1, left as u32)]);
    assert_eq!(room.nodes[0].peer.counters().remote_hands_expired, 0);
}

#[test]
fn a_holders_peer_dies_its_hand_lets_go_and_the_other_hands_hold_on() {
    let (mut room, hub) = Room::new(AuthorityPolicy::Free, 0.02, true);
    let rest = room.particles(0);
    let [left, right, top] = three(&rest);
    let t0 = room.t;
    let plans = [
        plan(
            left,
            rest[left],
            t0 + 0.2,
            Vec3::new(-0.03, 0.0, 0.0),
            t0 + 0.6,
            0.5,
            t0 + 10.0,
        ),
        plan(
            right,
            room.particles(1)[right],
            t0 + 0.4,
            Vec3::new(0.03, 0.0, 0.0),
            t0 + 0.6,
            0.5,
            t0 + 10.0,
        ),
        plan(
            top,
            room.particles(2)[top],
            t0 + 0.4,
            Vec3::new(0.0, 0.03, 0.0),
            t0 + 0.6,
            0.5,
            t0 + 10.0,
        ),
    ];
    room.run(1.5, &mut |i, now, t| plans[i].hand(now, t));
    assert_eq!(room.holders(0).len(), 3, "{:?}", room.holders(0));
    // A dies mid-hold: its process stops, its links go silent
    hub.kill(A);
    room.nodes[1].link_dead = true;
    room.run(2.0, &mut |i, now, t| plans[i].hand(now, t));
    let host = room.nodes[0].peer.counters();
    assert_eq!(host.remote_hands_taken, 2);
    // let go when silent past the timeout, or when the peer left: never kept
    assert_eq!(room.nodes[0].peer.remote_hands_applied(), 1);
    let expect = vec![(HOST, 1, left as u32), (B, 1, top as u32)];
    assert_eq!(room.holders(0), expect);
    assert_eq!(room.holders(2), expect);
    // B still pulls its particle on the owner's body
    let t = room.t;
    let d = room.particles(0)[top].distance(plans[2].goal(t));
    assert!(
        d < 0.012,
        "B's particle is {d} m from B's hand on the owner"
    );
}

#[test]
fn locked_refuses_remote_hands_and_owner_must_agree_asks_the_owner() {
    for (policy, agree) in [
        (AuthorityPolicy::Locked, true),
        (AuthorityPolicy::OwnerMustAgree, false),
        (AuthorityPolicy::OwnerMustAgree, true),
    ] {
        let (mut room, _hub) = Room::new(policy, 0.02, agree);
        let rest = room.particles(0);
        let [left, right, _] = three(&rest);
        let t0 = room.t;
        let plans = [
            plan(left, rest[left], t0 + 0.2, Vec3::ZERO, t0, 1.0, t0 + 3.0),
            plan(
                right,
                room.particles(1)[right],
                t0 + 0.5,
                Vec3::new(0.04, 0.0, 0.0),
                t0 + 0.7,
                0.5,
                t0 + 3.0,
            ),
        ];
        room.run(2.0, &mut |i, now, t| {
            plans.get(i).and_then(|p| p.hand(now, t))
        });
        let moved = room.particles(0)[right].distance(rest[right]);
        let a = &room.nodes[1];
        let host = room.nodes[0].peer.counters();
        let what = format!("{policy:?}, owner agrees: {agree}");
        if policy == AuthorityPolicy::OwnerMustAgree && agree {
            assert_eq!(host.remote_hands_taken, 1, "{what}");
            assert!(a
                .first(|e| matches!(e, Event::AuthorityDenied(_)))
                .is_none());
            assert!(
                moved > 0.03,
                "{what}: the hand moved its particle {moved} m"
            );
        } else {
            assert!(
                a.first(|e| matches!(e, Event::AuthorityDenied(_)))
                    .is_some(),
                "{what}: A's grab was not refused"
            );
            assert_eq!(host.remote_hands_taken, 0, "{what}");
            assert!(
                moved < 0.01,
                "{what}: the refused hand moved its particle {moved} m"
            );
            assert!(a.peer.held(1).is_none(), "{what}: A still holds");
            if policy == AuthorityPolicy::OwnerMustAgree {
                assert_eq!(host.remote_hands_refused, 1, "{what}");
                assert_eq!(a.peer.counters().remote_hands_denied, 1, "{what}");
            }
        }
        assert_eq!(room.nodes[0].peer.session().owner(room.ball), Some(HOST));
    }
}

#[test]
fn hostile_remote_hands_are_refused_and_counted_and_change_nothing() {
    let (mut room, _hub) = Room::new(AuthorityPolicy::Free, 0.0, true);
    let before = room.particles(0);
    let ball = room.ball;
    // the host's avatar head: an object, but no body to hold
    let head = room.nodes[0].peer.avatar_parts()[0].unwrap();
    let good = RemoteHand {
        object: ball,
        hand: 1,
        grab: 1,
        particle: 0,
        pos: before[0].to_array(),
        vel: [0.0; 3],
        release: false,
    };
    let hostile = [
        RemoteHand {
            pos: [f32::NAN, 0.0, 0.0],
            ..good.clone()
        },
        RemoteHand {
            vel: [0.0, f32::INFINITY, 0.0],
            ..good.clone()
        },
        RemoteHand {
            particle: 1_000_000,
            ..good.clone()
        },
        RemoteHand {
            hand: 7,
            ..good.clone()
        },
        RemoteHand {
            grab: 0,
            ..good.clone()
        },
        // a pose-only object: no particles to hold
        RemoteHand {
            object: head,
            ..good.clone()
        },
    ];
    let now = room.now;
    for m in &hostile {
        let to = MessageTarget::OwnerOf(m.object);
        room.nodes[1]
            .peer
            .send(now, to, Delivery::Unreliable, m)
            .unwrap();
    }
    // an object nobody can see: the host refuses to relay it
    let unseen = RemoteHand {
        object: NetId(9_999),
        ..good.clone()
    };
    let r = room.nodes[1].peer.send(
        now,
        MessageTarget::OwnerOf(unseen.object),
        Delivery::Unreliable,
        &unseen,
    );
    assert!(r.is_ok(), "the sender cannot know: the host checks");
    room.run(0.5, &mut |_, _, _| None);
    let host = room.nodes[0].peer.counters();
    assert_eq!(host.remote_hands_malformed, hostile.len() as u64);
    assert_eq!(host.remote_hands_taken, 0);
    let no_target = room.nodes[0].peer.session().stats().messages.refused
        [&softsync_net::MessageRefusal::NoSuchTarget];
    assert_eq!(no_target, 1);
    // a thousand a second for a second, from a peer that holds nothing: the host's relay
    // takes its unreliable rate (240/s after a burst of 240) and drops the rest, counted
    let refused_before = rate_limited(&room.nodes[0]);
    let mut sent = 0u32;
    for k in 0..60 {
        let m = RemoteHand {
            grab: 2 + k,
            ..good.clone()
        };
        for _ in 0..16 {
            // a modified client skips its own bucket: straight into the session
            let bytes = room.nodes[2].peer.message_types().encode(&m).unwrap();
            let _ = room.nodes[2].peer.send_message(
                room.now,
                bytes.0,
                MessageTarget::OwnerOf(ball),
                Delivery::Unreliable,
                bytes.1,
            );
            sent += 1;
        }
        room.run(DT, &mut |_, _, _| None);
    }
    assert!(sent >= 960);
    let limited = rate_limited(&room.nodes[2]) + rate_limited(&room.nodes[0]) - refused_before;
    assert!(limited > 400, "only {limited} of {sent} refused for rate");
    // a new grab every step: the owner takes one per hand per 100 ms at most, and answers
    // none of them (an answer goes only with a refusal), so nothing floods back
    let host = room.nodes[0].peer.counters();
    assert!(host.remote_hands_too_fast > 30, "{host:?}");
    assert!(host.remote_hands_taken <= 11, "{host:?}");
    // once it stops, its hand goes silent and is let go; the ball is where it was
    room.run(1.5, &mut |_, _, _| None);
    assert_eq!(room.nodes[0].peer.remote_hands_applied(), 0);
    assert!(room.holders(1).is_empty());
    let after = room.particles(0);
    let moved = max_distance(&before, &after);
    assert!(moved < 0.003, "the ball moved {moved} m");
    for n in &room.nodes {
        assert_eq!(n.peer.session().owner(ball), Some(HOST));
    }
}

fn rate_limited(n: &Node) -> u64 {
    n.peer
        .session()
        .stats()
        .messages
        .refused
        .get(&softsync_net::MessageRefusal::RateLimited)
        .copied()
        .unwrap_or(0)
}

/// The host's hand on the ball's leftmost particle (from `t0 + 0.2`), A's on its rightmost
/// (from `t0 + 0.4`), each pulling `pull_m` outward from `t0 + pull_at` over 0.5 s, both
/// letting go at `t0 + release`.
fn both_sides(room: &mut Room, t0: f32, pull_m: f32, pull_at: f32, release: f32) -> [Plan; 2] {
    let rest = room.particles(0);
    let [left, right, _] = three(&rest);
    let out = |s: f32| Vec3::new(s * pull_m, 0.0, 0.0);
    [
        plan(
            left,
            rest[left],
            t0 + 0.2,
            out(-1.0),
            t0 + pull_at,
            0.5,
            t0 + release,
        ),
        plan(
            right,
            room.particles(1)[right],
            t0 + 0.4,
            out(1.0),
            t0 + pull_at,
            0.5,
            t0 + release,
        ),
    ]
}

#[test]
fn a_peer_that_owns_nothing_tears_the_body_between_two_holding_hands() {
    let (mut room, _hub) = Room::new(AuthorityPolicy::Free, 0.02, true);
    let ball = room.ball;
    let untouched = room.nodes[0].peer.topology_hash(ball).unwrap();
    let t0 = room.t;
    // the host holds the left side, A the right; both pull a little
    let plans = both_sides(&mut room, t0, 0.02, 0.6, 4.0);
    let hands = |i: usize, now: Instant, t: f32| plans.get(i).and_then(|p| p.hand(now, t));
    room.run(1.3, &mut |i, now, t| hands(i, now, t));
    assert_eq!(room.holders(2).len(), 2, "{:?}", room.holders(2));
    // B, which owns and holds nothing, strokes across the top of the ball, front to back
    let c = room.nodes[2].peer.shown_state(room.now, ball).unwrap().pos;
    let path: Vec<Vec3> = (0..5)
        .map(|k| c + Vec3::new(0.0, 0.02, -0.05 + 0.025 * k as f32))
        .collect();
    for w in path.windows(2) {
        let now = room.now;
        room.nodes[2]
            .peer
            .tear(now, ball, w[0], w[1], Vec3::Y * 0.04)
            .unwrap();
        room.run(0.1, &mut |i, now, t| hands(i, now, t));
    }
    let now = room.now;
    room.nodes[2].peer.lift(now, ball).unwrap();
    room.run(1.0, &mut |i, now, t| hands(i, now, t));
    // the owner applied it as its own; every peer holds the same torn mesh
    let torn = room.nodes[0].peer.topology_hash(ball).unwrap();
    assert_ne!(torn, untouched, "the ball was not torn");
    for n in &room.nodes {
        assert_eq!(n.peer.topology_hash(ball), Some(torn), "{:?}", n.peer.me());
        assert_eq!(n.peer.session().owner(ball), Some(HOST));
        assert!(n.first(|e| matches!(e, Event::AuthorityAsked(_))).is_none());
    }
    let host = room.nodes[0].peer.counters();
    assert!(host.blade_requests_applied >= 1, "{host:?}");
    assert_eq!(host.blade_requests_refused, 0);
    assert_eq!(room.nodes[0].peer.objects()[&ball].topology, 5);
    // the two hands held on through the tear
    assert_eq!(room.holders(2).len(), 2, "{:?}", room.holders(2));
    // a Locked class: a non-owner's blade is refused where it starts
    let (mut locked, _hub) = Room::new(AuthorityPolicy::Locked, 0.0, true);
    let c = locked.nodes[2]
        .peer
        .shown_state(locked.now, locked.ball)
        .unwrap()
        .pos;
    let (now, ball) = (locked.now, locked.ball);
    let r = locked.nodes[2]
        .peer
        .tear(now, ball, c, c + Vec3::X * 0.02, Vec3::Y * 0.04);
    assert!(r.is_err());
    locked.run(0.5, &mut |_, _, _| None);
    assert_eq!(
        locked.nodes[0].peer.topology_hash(ball),
        locked.nodes[2].peer.topology_hash(ball)
    );
    assert_eq!(locked.nodes[0].peer.objects()[&ball].topology, 0);
}

#[test]
fn a_cut_between_two_holding_hands_leaves_each_hand_on_its_piece() {
    let (mut room, _hub) = Room::new(AuthorityPolicy::Free, 0.02, true);
    let ball = room.ball;
    let t0 = room.t;
    // the host holds the left side, A the right; after the cut both pull outward
    let plans = both_sides(&mut room, t0, 0.04, 1.5, 4.0);
    let hands = |i: usize, now: Instant, t: f32| plans.get(i).and_then(|p| p.hand(now, t));
    room.run(1.0, &mut |i, now, t| hands(i, now, t));
    assert_eq!(room.holders(2).len(), 2, "{:?}", room.holders(2));
    // B, which owns and holds nothing, cuts the ball in two between the hands
    let c = room.nodes[2].peer.shown_state(room.now, ball).unwrap().pos;
    let now = room.now;
    room.nodes[2].peer.cut(now, ball, c, Vec3::X).unwrap();
    room.run(1.2, &mut |i, now, t| hands(i, now, t));
    let pieces = room.nodes[0].id_of("softball");
    assert_eq!(pieces.len(), 2, "{pieces:?}");
    assert!(!pieces.contains(&ball));
    // each hand holds a piece (the host's here, A's as a remote hand), never let go
    let host_holds = room.nodes[0].peer.held(1).map(|h| h.0);
    let a_holds = room.nodes[1].peer.held(1).map(|h| h.0);
    assert!(
        host_holds.is_some_and(|p| pieces.contains(&p)),
        "{host_holds:?}"
    );
    assert!(a_holds.is_some_and(|p| pieces.contains(&p)), "{a_holds:?}");
    assert_ne!(host_holds, a_holds, "both hands on one piece");
    assert!(room.nodes[1].peer.holds_remotely(1));
    for i in 0..2 {
        let n = &room.nodes[i];
        assert_eq!(n.peer.counters().holds_kept_through_cuts, 1, "node {i}");
        assert!(n.first(|e| matches!(e, Event::GrabEnded { .. })).is_none());
    }
    // A's pull moves its piece on the owner's world
    let a_piece = a_holds.unwrap();
    let hand = plans[1].goal(room.t);
    let on_owner = room.nodes[0]
        .peer
        .local_state(a_piece)
        .unwrap()
        .particles
        .iter()
        .map(|p| p.distance(hand))
        .fold(f32::INFINITY, f32::min);
    assert!(on_owner < 0.012, "A's piece is {on_owner} m from A's hand");
    for id in &pieces {
        let who: Vec<PeerId> = room.nodes[2]
            .peer
            .holders(*id)
            .iter()
            .map(|h| h.peer)
            .collect();
        assert_eq!(who.len(), 1, "piece {id:?}: {who:?}");
    }
}
