//! The churn soak's invariants, as pure functions of what each peer's dump showed at one moment
//! and what the scheduler did to each process: [`failures`] lists what does not hold now,
//! [`Streaks`] turns a failure that lasts longer than its grace into one violation.
//!
//! Safety (must hold at once, the grace only covers dumps taken at different moments): one host
//! per term; no object owned by two peers. Liveness (must hold again within a few heartbeat
//! windows after any event): exactly one peer acts as host; every peer lists the same members,
//! every live process among them and no dead one; every object's owner is a live member; no
//! scene object missing from any view.

use std::collections::{BTreeMap, BTreeSet};

use softsync_peer::dump::DumpLine;

/// Where a process stands, as the scheduler knows it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Life {
    /// Running and settled: its view is checked.
    Checked,
    /// Running, but just joined or just resumed: not checked yet, but a member.
    Settling,
    /// SIGSTOPped: its last view is stale; it may or may not still be listed.
    Stopped,
    /// Killed or left this long ago (ms).
    Ended(u64),
}

/// One process at the moment checked.
#[derive(Clone, Debug)]
pub struct PeerAt<'a> {
    /// Its peer id (0 before its first dump line).
    pub id: u64,
    pub life: Life,
    /// Its last dump line at or before the moment.
    pub line: Option<&'a DumpLine>,
}

/// Safety checks: a failure must be gone within this (dumps are 100 ms apart; a grant or a
/// step-down takes a link's delay).
pub const SAFETY_GRACE_MS: u64 = 1_500;
/// Liveness checks: a failure must be gone within this after the event that caused it
/// (detection 1 s, election, re-grant, a joiner's welcome).
pub const LIVENESS_GRACE_MS: u64 = 6_000;
/// An ended process may still be listed for this long (the heartbeat timeout and a margin).
pub const DEAD_LISTED_MS: u64 = 3_000;

/// What fails at this moment: (check, detail). `scene` are the ids of the scene's objects.
pub fn failures(peers: &[PeerAt<'_>], scene: &BTreeSet<u32>) -> Vec<(&'static str, String)> {
    let mut out = Vec::new();
    let checked: Vec<(&PeerAt, &DumpLine)> = peers
        .iter()
        .filter(|p| p.life == Life::Checked)
        .filter_map(|p| p.line.map(|l| (p, l)))
        .collect();
    let alive: BTreeSet<u64> = peers
        .iter()
        .filter(|p| matches!(p.life, Life::Checked | Life::Settling) && p.id != 0)
        .map(|p| p.id)
        .collect();
    let long_dead: BTreeSet<u64> = peers
        .iter()
        .filter(|p| matches!(p.life, Life::Ended(ago) if ago > DEAD_LISTED_MS) && p.id != 0)
        .map(|p| p.id)
        .collect();
    let ended: BTreeSet<u64> = peers
        .iter()
        .filter(|p| matches!(p.life, Life::Ended(_)) && p.id != 0)
        .map(|p| p.id)
        .collect();

    // safety: one host per term
    let mut hosts: BTreeMap<u32, BTreeSet<u64>> = BTreeMap::new();
    for (_, l) in &checked {
        if let Some(h) = l.host {
            hosts.entry(l.term).or_default().insert(h);
        }
    }
    for (term, hs) in &hosts {
        if hs.len() > 1 {
            out.push(("two_hosts_in_a_term", format!("term {term}: hosts {hs:?}")));
        }
    }
    // safety: no object with two owners (each owner says so itself)
    let mut claims: BTreeMap<u32, BTreeSet<u64>> = BTreeMap::new();
    for (_, l) in &checked {
        for o in l.objects.iter().filter(|o| o.owner == l.peer) {
            claims.entry(o.id).or_default().insert(l.peer);
        }
    }
    for (id, owners) in &claims {
        if owners.len() > 1 {
            out.push(("two_owners", format!("object {id}: owned by {owners:?}")));
        }
    }

    // liveness: exactly one peer acts as host (a stopped one's stale claim counts: it must
    // step down once it runs again)
    let acting: BTreeSet<u64> = peers
        .iter()
        .filter(|p| !matches!(p.life, Life::Ended(_)))
        .filter_map(|p| p.line)
        .filter(|l| l.host == Some(l.peer))
        .map(|l| l.peer)
        .collect();
    if acting.len() != 1 {
        out.push(("not_one_host", format!("acting as host: {acting:?}")));
    }
    // liveness: the same members everywhere, every live process listed, no long-dead one
    let first = checked
        .first()
        .map(|(_, l)| l.members.iter().copied().collect::<BTreeSet<_>>());
    for (_, l) in &checked {
        let m: BTreeSet<u64> = l.members.iter().copied().collect();
        let missing: Vec<u64> = alive.difference(&m).copied().collect();
        let dead: Vec<u64> = m.intersection(&long_dead).copied().collect();
        if !missing.is_empty() || !dead.is_empty() {
            out.push((
                "members",
                format!("peer {}: missing {missing:?}, dead listed {dead:?}", l.peer),
            ));
        } else if first.as_ref().is_some_and(|f| *f != m) {
            out.push((
                "members",
                format!("peer {} lists {m:?}, another {first:?}", l.peer),
            ));
        }
    }
    // liveness: every object owned by a live member (in the host's view)
    if let Some((_, h)) = checked.iter().find(|(_, l)| l.host == Some(l.peer)) {
        for o in &h.objects {
            if ended.contains(&o.owner) || !h.members.contains(&o.owner) {
                out.push((
                    "owner_gone",
                    format!("object {}: owner {} is not a live member", o.id, o.owner),
                ));
            }
        }
    }
    // liveness: no scene object missing from a view
    for (_, l) in &checked {
        let have: BTreeSet<u32> = l.objects.iter().map(|o| o.id).collect();
        let lost: Vec<u32> = scene.difference(&have).copied().collect();
        if !lost.is_empty() {
            out.push(("object_lost", format!("peer {} lacks {lost:?}", l.peer)));
        }
    }
    out
}

/// Failures that outlast their grace, each counted once per unbroken streak.
#[derive(Debug, Default)]
pub struct Streaks {
    /// Since when each (check, subject) has failed, and whether it was counted already.
    since: BTreeMap<(&'static str, String), (u64, bool)>,
}

impl Streaks {
    /// Feed the failures at `now_ms`; returns those that just became violations.
    pub fn update(
        &mut self,
        now_ms: u64,
        failing: &[(&'static str, String)],
    ) -> Vec<(&'static str, String)> {
        // a failure's subject is the text before the first ':' (an object, a peer, a term)
        let keys: BTreeMap<(&'static str, String), &String> = failing
            .iter()
            .map(|(c, d)| ((*c, d.split(':').next().unwrap_or("").to_owned()), d))
            .collect();
        self.since.retain(|k, _| keys.contains_key(k));
        let mut new = Vec::new();
        for (k, detail) in keys {
            let grace = match k.0 {
                "two_hosts_in_a_term" | "two_owners" => SAFETY_GRACE_MS,
                _ => LIVENESS_GRACE_MS,
            };
            let e = self.since.entry(k.clone()).or_insert((now_ms, false));
            if !e.1 && now_ms.saturating_sub(e.0) > grace {
                e.1 = true;
                new.push((k.0, detail.clone()));
            }
        }
        new
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::views::test_line;

    fn line(peer: u64, host: u64, term: u32, members: &[u64], owners: &[(u32, u64)]) -> DumpLine {
        test_line(peer, host, term, 0, members, owners)
    }

    fn at<'a>(id: u64, life: Life, l: &'a DumpLine) -> PeerAt<'a> {
        PeerAt {
            id,
            life,
            line: Some(l),
        }
    }

    #[test]
    fn a_healthy_room_passes_and_each_broken_invariant_is_named() {
        let scene: BTreeSet<u32> = [1, 2].into();
        let a = line(10, 10, 1, &[10, 20], &[(1, 10), (2, 20)]);
        let b = line(20, 10, 1, &[10, 20], &[(1, 10), (2, 20)]);
        let ok = [at(10, Life::Checked, &a), at(20, Life::Checked, &b)];
        assert!(
            failures(&ok, &scene).is_empty(),
            "{:?}",
            failures(&ok, &scene)
        );

        // two owners of object 1, another host in the same term, a lost object, a member
        // missing
        let b2 = line(20, 20, 1, &[20], &[(1, 20)]);
        let bad = [at(10, Life::Checked, &a), at(20, Life::Checked, &b2)];
        let f: BTreeSet<&str> = failures(&bad, &scene).iter().map(|(c, _)| *c).collect();
        for c in [
            "two_owners",
            "two_hosts_in_a_term",
            "not_one_host",
            "members",
            "object_lost",
        ] {
            assert!(f.contains(c), "{c} not found in {f:?}");
        }

        // the host killed 5 s ago, still the owner of object 1 in the new host's view
        let b3 = line(20, 20, 2, &[20], &[(1, 10), (2, 20)]);
        let dead = [at(10, Life::Ended(5_000), &a), at(20, Life::Checked, &b3)];
        let f: Vec<_> = failures(&dead, &scene);
        assert!(f.iter().any(|(c, _)| *c == "owner_gone"), "{f:?}");
        assert!(!f.iter().any(|(c, _)| *c == "not_one_host"), "{f:?}");
    }

    #[test]
    fn a_failure_counts_once_and_only_after_its_grace() {
        let mut s = Streaks::default();
        let f = vec![("members", "peer 3: missing [4]".to_owned())];
        assert!(s.update(0, &f).is_empty());
        assert!(s.update(LIVENESS_GRACE_MS, &f).is_empty());
        assert_eq!(s.update(LIVENESS_GRACE_MS + 1000, &f).len(), 1);
        assert!(s.update(LIVENESS_GRACE_MS + 2000, &f).is_empty());
        // healed, then failing again: a new streak
        assert!(s.update(LIVENESS_GRACE_MS + 3000, &[]).is_empty());
        assert!(s.update(20_000, &f).is_empty());
        let two = vec![("two_owners", "object 1: owned by {1, 2}".to_owned())];
        assert!(s.update(0, &two).is_empty());
        assert_eq!(s.update(SAFETY_GRACE_MS + 1, &two).len(), 1);
    }
}
