//! The room of honest sessions a script plays in, the hostile peer beside them, and how
//! each step is played.

use super::*;

/// An honest peer.
pub(super) struct Peer {
    pub(super) id: PeerId,
    pub(super) session: Session,
    /// Bumped when it joins again with a fresh session.
    pub(super) incarnation: u32,
    /// Crashed or left: never driven again.
    pub(super) gone: bool,
    /// Its loop stalls: nothing is processed; datagrams for it wait in `inbox`.
    pub(super) frozen: bool,
    pub(super) inbox: VecDeque<(PeerId, Vec<u8>)>,
    /// Refused while joining: done.
    pub(super) refused: bool,
    /// When it last said `Hello` (join retries).
    pub(super) asked_at: Instant,
}

impl Peer {
    pub(super) fn active(&self) -> bool {
        !self.gone && !self.frozen
    }
}

/// A datagram of the room's, kept for replays.
pub(super) struct Captured {
    pub(super) from: PeerId,
    pub(super) to: PeerId,
    /// The sender's and the recipient's incarnations when it was sent.
    pub(super) incarnations: (Option<u32>, Option<u32>),
    pub(super) bytes: Vec<u8>,
}

/// The room a script plays in.
pub(super) struct Room {
    pub(super) setup: Setup,
    pub(super) cfg: SessionConfig,
    pub(super) now: Instant,
    pub(super) deadline: Instant,
    pub(super) peers: Vec<Peer>,
    pub(super) puppet: Session,
    pub(super) attached: bool,
    pub(super) captured: VecDeque<Captured>,
    /// Every datagram sent among the room, when a corpus is made.
    pub(super) keep_all: Option<Vec<Vec<u8>>>,
    pub(super) cuts: BTreeSet<(PeerId, PeerId)>,
    pub(super) rng: SeededRng,
    pub(super) loss: f64,
    pub(super) rejoins: u32,
    pub(super) hostile_spoke: bool,
    pub(super) outcome: Outcome,
    pub(super) step: usize,
}

impl Room {
    pub(super) fn new(setup: Setup, keep: bool) -> Room {
        let cfg = room_config(&setup);
        let now = Instant::ZERO;
        let mut puppet_cfg = cfg.clone();
        if setup.keyed {
            // an insider holds the key; anyone else answers a challenge with another
            let secret: &[u8] = if setup.insider {
                SECRET
            } else {
                b"a guess at the room's secret"
            };
            puppet_cfg.room_key = Some(RoomKey::new(secret, HOSTILE.0).for_room("fuzz"));
        }
        let mut room = Room {
            setup,
            cfg,
            now,
            deadline: now + MAX_VIRTUAL_TIME,
            peers: Vec::new(),
            puppet: Session::join(HOSTILE, FIRST_HOST, puppet_cfg, now),
            attached: setup.hostile_joins,
            captured: VecDeque::new(),
            keep_all: keep.then(Vec::new),
            cuts: BTreeSet::new(),
            rng: SeededRng::new(0x5eed_0000 ^ u64::from(setup.seed)),
            loss: 0.0,
            rejoins: 0,
            hostile_spoke: false,
            outcome: Outcome::default(),
            step: 0,
        };
        let host = Session::host(FIRST_HOST, room.config_of(FIRST_HOST), now);
        room.add_peer(host);
        let members = if setup.three_members { 3 } else { 2 };
        for i in 0..members {
            let id = PeerId(2 + i);
            let s = Session::join(id, FIRST_HOST, room.config_of(id), now);
            room.add_peer(s);
        }
        room.wait(Duration::from_millis(300));
        room.deadline = room.now + MAX_VIRTUAL_TIME;
        room
    }

    pub(super) fn add_peer(&mut self, session: Session) {
        self.peers.push(Peer {
            id: session.local_id(),
            session,
            incarnation: 0,
            gone: false,
            frozen: false,
            inbox: VecDeque::new(),
            refused: false,
            asked_at: self.now,
        });
    }

    /// An honest peer's configuration: the room's, with its own key (the room's secret,
    /// its own nonce seed) in a room with a key.
    pub(super) fn config_of(&self, id: PeerId) -> SessionConfig {
        let mut c = self.cfg.clone();
        if self.setup.keyed {
            c.room_key = Some(RoomKey::new(SECRET, id.0).for_room("fuzz"));
        }
        c
    }

    // ------------------------------------------------------------ picking

    /// A live, running honest peer.
    pub(super) fn pick_active(&self, b: u8) -> Option<usize> {
        let live: Vec<usize> = (0..self.peers.len())
            .filter(|i| self.peers.get(*i).is_some_and(Peer::active))
            .collect();
        pick(&live, b).copied()
    }

    /// A live honest peer, frozen or not.
    pub(super) fn pick_live(&self, b: u8) -> Option<usize> {
        let live: Vec<usize> = (0..self.peers.len())
            .filter(|i| self.peers.get(*i).is_some_and(|p| !p.gone))
            .collect();
        pick(&live, b).copied()
    }

    pub(super) fn peer_of(&self, id: PeerId) -> Option<&Peer> {
        self.peers.iter().find(|p| p.id == id && !p.gone)
    }

    pub(super) fn incarnation(&self, id: PeerId) -> Option<u32> {
        if id == HOSTILE {
            return Some(0);
        }
        self.peers
            .iter()
            .find(|p| p.id == id)
            .map(|p| p.incarnation)
    }

    // ------------------------------------------------------------ the network

    /// A datagram of the room's (an honest peer's, or the attached puppet's): captured,
    /// then lost, cut off, or delivered.
    pub(super) fn send(&mut self, from: PeerId, to: PeerId, bytes: Vec<u8>) {
        if self.captured.len() >= CAPTURED {
            self.captured.pop_front();
        }
        self.captured.push_back(Captured {
            from,
            to,
            incarnations: (self.incarnation(from), self.incarnation(to)),
            bytes: bytes.clone(),
        });
        if let Some(all) = &mut self.keep_all {
            all.push(bytes.clone());
        }
        if self.loss > 0.0 && self.rng.chance(self.loss) {
            return;
        }
        let pair = (from.min(to), from.max(to));
        if self.cuts.contains(&pair) {
            return;
        }
        self.outcome.datagrams += 1;
        self.arrive(from, to, bytes);
    }

    /// `bytes` reach `to` (a frozen peer finds them when it resumes).
    pub(super) fn arrive(&mut self, from: PeerId, to: PeerId, bytes: Vec<u8>) {
        let now = self.now;
        if to == HOSTILE {
            self.puppet.handle_packet(now, from, &bytes);
            return;
        }
        if let Some(p) = self.peers.iter_mut().find(|p| p.id == to && !p.gone) {
            if p.frozen {
                if p.inbox.len() < INBOX {
                    p.inbox.push_back((from, bytes));
                }
            } else {
                p.session.handle_packet(now, from, &bytes);
            }
        }
    }

    /// The hostile peer (or a made-up one) sends `bytes` to `to`: no loss, no cut.
    pub(super) fn inject(&mut self, from: PeerId, to: PeerId, bytes: Vec<u8>) {
        self.hostile_spoke = true;
        self.arrive(from, to, bytes);
    }

    /// Deliver what the running peers send, round after round, until quiet (bounded).
    pub(super) fn flush(&mut self) {
        let now = self.now;
        for _ in 0..FLUSH_ROUNDS {
            let mut out = Vec::new();
            for p in self.peers.iter_mut().filter(|p| p.active()) {
                let before = out.len();
                while let Some(t) = p.session.poll_transmit(now) {
                    out.push((p.id, t));
                    assert!(
                        out.len() - before < MAX_BURST,
                        "peer {} never stops sending (step {})",
                        p.id.0,
                        self.step
                    );
                }
            }
            if self.attached {
                while let Some(t) = self.puppet.poll_transmit(now) {
                    out.push((HOSTILE, t));
                    assert!(out.len() < 4 * MAX_BURST, "the puppet never stops sending");
                }
            }
            self.handle_events();
            if out.is_empty() {
                break;
            }
            for (from, t) in out {
                self.send(from, t.to, t.payload);
            }
        }
        self.handle_events();
    }

    /// Timers due now, join retries, then a flush.
    pub(super) fn run_due(&mut self) {
        let now = self.now;
        for p in self.peers.iter_mut().filter(|p| p.active()) {
            if p.session.poll_timeout().is_some_and(|t| t <= now) {
                p.session.handle_timeout(now);
            }
        }
        if self.attached && self.puppet.poll_timeout().is_some_and(|t| t <= now) {
            self.puppet.handle_timeout(now);
        }
        self.retry_joins();
        self.flush();
    }

    /// A joiner that had no answer for a while asks the host some connected peer follows
    /// (its contact may have crashed, or redirected it to a host that did).
    pub(super) fn retry_joins(&mut self) {
        let now = self.now;
        let hosts: Vec<PeerId> = self
            .peers
            .iter()
            .filter(|p| p.active() && p.session.is_connected())
            .filter_map(|p| p.session.host_id())
            .collect();
        for (k, p) in self.peers.iter_mut().enumerate() {
            if !p.active() || p.refused || p.session.is_connected() {
                continue;
            }
            if now < p.asked_at + JOIN_RETRY {
                continue;
            }
            let others: Vec<PeerId> = hosts.iter().copied().filter(|h| *h != p.id).collect();
            if let Some(contact) = pick(&others, (k + self.rejoins as usize) as u8) {
                p.session.join_via(now, *contact);
            }
            p.asked_at = now;
        }
    }

    pub(super) fn next_deadline(&self) -> Option<Instant> {
        let peers = self
            .peers
            .iter()
            .filter(|p| p.active())
            .filter_map(|p| p.session.poll_timeout());
        let puppet = self.attached.then(|| self.puppet.poll_timeout()).flatten();
        let joins = self
            .peers
            .iter()
            .filter(|p| p.active() && !p.refused && !p.session.is_connected())
            .map(|p| p.asked_at + JOIN_RETRY);
        peers.chain(puppet).chain(joins).min()
    }

    /// Let `d` pass (within the script's time), jumping from deadline to deadline.
    pub(super) fn wait(&mut self, d: Duration) {
        let end = (self.now + d).min(self.deadline.max(self.now));
        self.run_due();
        while let Some(next) = self.next_deadline() {
            let next = next.max(self.now + Duration::from_millis(1));
            if next > end {
                break;
            }
            self.now = next;
            self.run_due();
        }
        self.now = end;
        self.run_due();
    }

    /// Events of every honest peer: asks answered, a dropped peer joins again with a fresh
    /// session (what the peer layer does), the rest counted.
    pub(super) fn handle_events(&mut self) {
        let now = self.now;
        let agree = !self.setup.refuse_asks;
        let mut rejoin = Vec::new();
        let o = &mut self.outcome;
        for (i, p) in self.peers.iter_mut().enumerate() {
            if p.gone {
                continue;
            }
            while let Some(e) = p.session.poll_event() {
                trace(|| format!("{:>8} ms  peer {}: {e:?}", now.as_micros() / 1000, p.id.0));
                match e {
                    Event::AuthorityAsked { id, by } => {
                        p.session.answer_authority(now, id, by, agree);
                    }
                    Event::Dropped { host, .. } => {
                        o.dropped += 1;
                        rejoin.push((i, host));
                    }
                    Event::Refused { .. } => {
                        o.refused += 1;
                        p.refused = true;
                    }
                    Event::Joined { .. } => o.joined += 1,
                    Event::HostChanged { .. } => o.host_changes += 1,
                    Event::AuthorityChanged { .. } => o.authority_changes += 1,
                    Event::AuthorityDenied { .. } => o.denied += 1,
                    Event::Spawned { .. } => o.spawned += 1,
                    Event::Despawned(_) => o.despawned += 1,
                    Event::Topology { .. } => o.topology += 1,
                    Event::Message(_) => o.messages += 1,
                    _ => {}
                }
            }
        }
        for (i, host) in rejoin {
            self.rejoin(i, host);
        }
    }

    /// Peer `i` was dropped: it joins `host` again with a fresh session.
    pub(super) fn rejoin(&mut self, i: usize, host: PeerId) {
        let now = self.now;
        if self.rejoins >= MAX_REJOINS {
            if let Some(p) = self.peers.get_mut(i) {
                p.refused = true;
            }
            return;
        }
        self.rejoins += 1;
        let Some(id) = self.peers.get(i).map(|p| p.id) else {
            return;
        };
        let contact = if host == id { FIRST_HOST } else { host };
        let cfg = self.config_of(id);
        let Some(p) = self.peers.get_mut(i) else {
            return;
        };
        // what the old session still had to say goes first
        let last: Vec<_> = std::iter::from_fn(|| p.session.poll_transmit(now)).collect();
        p.session = Session::join(id, contact, cfg, now);
        p.incarnation += 1;
        p.refused = false;
        p.asked_at = now;
        for t in last {
            self.send(id, t.to, t.payload);
        }
    }

    // ------------------------------------------------------------ steps

    pub(super) fn play(&mut self, step: &Step) {
        let now = self.now;
        match step {
            Step::Wait { ms, loss } => {
                self.loss = [0.0, 0.05, 0.2, 0.5][usize::from(*loss % 4)];
                self.wait(Duration::from_millis((u64::from(*ms) + 1) * 10));
            }
            Step::Spawn { peer, shape } => {
                let Some(i) = self.pick_active(*peer) else {
                    return;
                };
                let class = shape % 3;
                let particles = if class == 1 {
                    1 + usize::from(shape / 3 % 12)
                } else {
                    0
                };
                let pos = Vec3::new(f32::from(shape >> 4) * 0.2 - 1.5, 1.0, 0.5);
                let st = ObjectState {
                    pos,
                    rot: Quat::IDENTITY,
                    particles: (0..particles)
                        .map(|k| pos + Vec3::new(k as f32 * 0.02, 0.0, 0.0))
                        .collect(),
                };
                if let Some(p) = self.peers.get_mut(i) {
                    let _ = p.session.spawn(now, ClassId(u16::from(class)), st);
                }
            }
            Step::Grab { peer, object }
            | Step::Release { peer, object }
            | Step::Despawn { peer, object } => {
                let Some(i) = self.pick_active(*peer) else {
                    return;
                };
                let Some(p) = self.peers.get_mut(i) else {
                    return;
                };
                let Some(id) = pick(&p.session.object_ids(), *object).copied() else {
                    return;
                };
                let _ = match step {
                    Step::Grab { .. } => p.session.request_authority(now, id),
                    Step::Release { .. } => p.session.release_authority(now, id),
                    _ => p.session.despawn(now, id),
                };
            }
            Step::Move { peer, object, to } => {
                let Some(i) = self.pick_active(*peer) else {
                    return;
                };
                let Some(p) = self.peers.get_mut(i) else {
                    return;
                };
                let me = p.id;
                let owned: Vec<NetId> = p
                    .session
                    .object_ids()
                    .into_iter()
                    .filter(|id| p.session.owner(*id) == Some(me))
                    .collect();
                let Some(id) = pick(&owned, *object).copied() else {
                    return;
                };
                let n = p.session.particles_of(id).unwrap_or(0) as usize;
                let pos = Vec3::new(
                    f32::from(to & 15) * 0.1 - 0.8,
                    1.0 + f32::from(to >> 4) * 0.05,
                    0.2,
                );
                let st = ObjectState {
                    pos,
                    rot: Quat::from_rotation_y(f32::from(*to) * 0.05),
                    particles: (0..n)
                        .map(|k| pos + Vec3::new(k as f32 * 0.02, f32::from(*to) * 0.001, 0.0))
                        .collect(),
                };
                let _ = p.session.publish_state(now, id, &st);
            }
            Step::Say { peer, how, len } => {
                let Some(i) = self.pick_active(*peer) else {
                    return;
                };
                let others: Vec<PeerId> = self.peers.iter().map(|p| p.id).collect();
                let Some(p) = self.peers.get_mut(i) else {
                    return;
                };
                let first = p.session.object_ids().first().copied().unwrap_or(NetId(0));
                let delivery = match how % 4 {
                    0 => Delivery::Reliable,
                    1 => Delivery::Unreliable,
                    2 => Delivery::Retained,
                    _ => Delivery::ObjectState(first),
                };
                let to = match (how >> 2) % 4 {
                    0 => MessageTarget::Everyone,
                    1 => MessageTarget::Host,
                    2 => MessageTarget::Peer(pick(&others, *len).copied().unwrap_or(FIRST_HOST)),
                    _ => MessageTarget::OwnerOf(first),
                };
                let kind = MessageKind(u16::from(how >> 7));
                let payload = vec![*how; usize::from(*len % 64)];
                let _ = p.session.send_message(now, kind, to, delivery, payload);
            }
            Step::Reshape { peer, object, how } => {
                let Some(i) = self.pick_active(*peer) else {
                    return;
                };
                let Some(p) = self.peers.get_mut(i) else {
                    return;
                };
                let me = p.id;
                let owned: Vec<NetId> = p
                    .session
                    .object_ids()
                    .into_iter()
                    .filter(|id| p.session.owner(*id) == Some(me))
                    .collect();
                let Some(id) = pick(&owned, *object).copied() else {
                    return;
                };
                let particles = p.session.particles_of(id).unwrap_or(0);
                let h = i32::from(*how);
                let (event, pieces) = match how % 4 {
                    0 => (
                        TopologyEvent::Tear {
                            from: [h * 100, 0, 0],
                            to: [h * 100 + 500, 0, 0],
                            blade: [0, 0, 1000],
                        },
                        Vec::new(),
                    ),
                    1 => (TopologyEvent::Lift, Vec::new()),
                    2 => (
                        TopologyEvent::Cut {
                            point: [0, h * 10, 0],
                            normal: [0, 32767, 0],
                            keep: 0,
                        },
                        if particles >= 2 {
                            vec![particles / 2, particles - particles / 2]
                        } else {
                            vec![1, 1]
                        },
                    ),
                    _ => (
                        TopologyEvent::Resolution {
                            level: how / 4 % 3,
                            particles: 1 + u32::from(how / 16),
                        },
                        Vec::new(),
                    ),
                };
                let _ = p.session.request_topology(now, id, event, pieces);
            }
            Step::Leave { peer } => {
                let Some(i) = self.pick_active(*peer) else {
                    return;
                };
                let Some(p) = self.peers.get_mut(i) else {
                    return;
                };
                p.session.leave(now);
                let id = p.id;
                let last: Vec<_> = std::iter::from_fn(|| p.session.poll_transmit(now)).collect();
                p.gone = true;
                for t in last {
                    self.send(id, t.to, t.payload);
                }
            }
            Step::Crash { peer } => {
                if let Some(i) = self.pick_live(*peer) {
                    if let Some(p) = self.peers.get_mut(i) {
                        p.gone = true;
                    }
                }
            }
            Step::Join { contact } => {
                let id = PeerId(self.peers.len() as u64 + 1);
                if id.0 > MAX_HONEST_ID {
                    return;
                }
                let Some(c) = self.pick_live(*contact).and_then(|i| self.peers.get(i)) else {
                    return;
                };
                let s = Session::join(id, c.id, self.config_of(id), now);
                self.add_peer(s);
            }
            Step::Freeze { peer } => {
                let Some(i) = self.pick_live(*peer) else {
                    return;
                };
                let thawed = self.peers.get_mut(i).and_then(|p| {
                    p.frozen = !p.frozen;
                    (!p.frozen).then(|| (p.id, std::mem::take(&mut p.inbox)))
                });
                if let Some((id, inbox)) = thawed {
                    for (from, bytes) in inbox {
                        self.arrive(from, id, bytes);
                    }
                }
            }
            Step::Cut { a, b } => {
                let (Some(a), Some(b)) = (self.pick_live(*a), self.pick_live(*b)) else {
                    return;
                };
                let (Some(a), Some(b)) = (self.peers.get(a), self.peers.get(b)) else {
                    return;
                };
                let pair = (a.id.min(b.id), a.id.max(b.id));
                if pair.0 != pair.1 && !self.cuts.remove(&pair) {
                    self.cuts.insert(pair);
                }
            }
            Step::Raw { to, from, bytes } => {
                let Some(to) = self.target(*to) else {
                    return;
                };
                let sender = if from & 0x40 != 0 {
                    PeerId(STRANGERS + u64::from(from & 0x3f))
                } else {
                    HOSTILE
                };
                let mut datagram = Vec::new();
                if from & 0x80 != 0 {
                    let term = self.peer_of(to).map_or(Term(0), |p| p.session.term());
                    PacketHeader {
                        term,
                        seq: bytes.first().copied().unwrap_or(0),
                        time_ms: now.wire_ms(),
                    }
                    .write(&mut datagram);
                }
                datagram.extend_from_slice(bytes);
                self.inject(sender, to, datagram);
            }
            Step::Replay {
                pick: k,
                how,
                at,
                value,
                to,
            } => self.replay(*k, *how, *at, *value, *to),
            Step::Forge { to, what, args } => {
                let Some(to) = self.target(*to) else {
                    return;
                };
                let Some(msg) = self.peer_of(to).map(|p| forge(&p.session, *what, *args)) else {
                    return;
                };
                self.puppet.send_raw_control(now, to, &msg);
                let out: Vec<_> = std::iter::from_fn(|| self.puppet.poll_transmit(now)).collect();
                for t in out {
                    if t.to == to {
                        self.inject(HOSTILE, to, t.payload);
                    } else if self.attached {
                        self.send(HOSTILE, t.to, t.payload);
                    }
                }
            }
            Step::Hellos { to, count } => {
                let Some(to) = self.target(*to) else {
                    return;
                };
                let digest = if count & 0x80 != 0 {
                    u64::from(*count)
                } else {
                    self.cfg.digest()
                };
                let hello = Control::Hello {
                    protocol: PROTOCOL_VERSION,
                    config_digest: digest,
                };
                for k in 0..=u64::from(count % 48) {
                    let d = datagram_with(Term(0), 0, &[(0, &hello)]);
                    self.inject(PeerId(STRANGERS + 100 + k), to, d);
                }
            }
            Step::Beacon { to, args } => {
                let Some(to) = self.target(*to) else {
                    return;
                };
                let term = self.peer_of(to).map_or(Term(0), |p| p.session.term());
                let term = Term((term.0 + u32::from(args[0] % 3)).saturating_sub(1));
                let summary = RoomSummary {
                    digest: if args[0] & 0x80 != 0 {
                        u64::from(args[1])
                    } else {
                        self.cfg.digest()
                    },
                    host: if args[0] & 0x40 != 0 {
                        PeerId(STRANGERS + u64::from(args[1]))
                    } else {
                        HOSTILE
                    },
                    host_join: u32::from(args[1] % 8),
                    members: u32::from(args[2] % 70),
                    tag: (args[0] & 0x20 != 0).then_some([args[2]; 16]),
                };
                let header = PacketHeader {
                    term,
                    seq: 0,
                    time_ms: now.wire_ms(),
                };
                self.inject(HOSTILE, to, encode_beacon(&header, &summary));
            }
            Step::Attach => self.attached = !self.attached,
        }
        self.flush();
    }

    /// The id of a live honest peer, for the hostile peer to send to.
    pub(super) fn target(&self, b: u8) -> Option<PeerId> {
        self.pick_live(b)
            .and_then(|i| self.peers.get(i))
            .map(|p| p.id)
    }

    pub(super) fn replay(&mut self, k: u8, how: u8, at: u8, value: u8, to: u8) {
        let Some(c) = self
            .captured
            .get(usize::from(k) % self.captured.len().max(1))
        else {
            return;
        };
        let (from, orig_to, incarnations, mut bytes) =
            (c.from, c.to, c.incarnations, c.bytes.clone());
        let other = self.target(to).unwrap_or(orig_to);
        let at = usize::from(at) % bytes.len().max(1);
        let (sender, recipient) = match how % 8 {
            // the same datagram again, late: a duplicate the network made (only between the
            // same sessions: a fresh session of the same peer would take it for its own, a
            // known limit of a header without a session number)
            0 => {
                if (self.incarnation(from), self.incarnation(orig_to)) != incarnations {
                    return;
                }
                if from == HOSTILE {
                    self.inject(from, orig_to, bytes);
                } else {
                    // an honest peer's datagram twice is the network's doing, not the
                    // hostile peer's
                    self.outcome.datagrams += 1;
                    self.arrive(from, orig_to, bytes);
                }
                self.flush();
                return;
            }
            1 => (HOSTILE, other),
            2 => (HOSTILE, orig_to),
            3 => (PeerId(STRANGERS + u64::from(value % 64)), orig_to),
            4 => {
                if let Some(b) = bytes.get_mut(at) {
                    *b ^= 1 << (value % 8);
                }
                (HOSTILE, other)
            }
            5 => {
                if let Some(b) = bytes.get_mut(at) {
                    *b = value;
                }
                (HOSTILE, other)
            }
            6 => {
                bytes.truncate(at);
                (HOSTILE, other)
            }
            _ => {
                // its sections twice over (a header is 5 bytes for small terms)
                let body = bytes.get(5.min(bytes.len())..).unwrap_or_default().to_vec();
                bytes.extend_from_slice(&body);
                (HOSTILE, other)
            }
        };
        self.inject(sender, recipient, bytes);
        self.flush();
    }
}
