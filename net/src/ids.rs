//! Identifiers shared by every module.

use serde::{Deserialize, Serialize};

/// A peer's transport address (given by the transport, stable for the peer's lifetime).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct PeerId(pub u64);

/// A networked object's id, unique in the room.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct NetId(pub u32);

/// An object class: index into [`crate::SessionConfig::classes`] (same on every peer).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct ClassId(pub u16);

/// Room term: bumped by every host migration; messages of an older term are ignored.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Term(pub u32);

/// Authority epoch of an object: bumped by every grant; ordered by (term, grant).
///
/// Including the term means a new host's reassignments always beat grants of the old term.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct AuthorityEpoch {
    /// Term in which the grant happened.
    pub term: u32,
    /// Grant counter within the term.
    pub grant: u32,
}

impl AuthorityEpoch {
    /// The next epoch in term `term` (never lower: the grant counter saturates).
    pub fn bumped(self, term: Term) -> Self {
        if term.0 > self.term {
            AuthorityEpoch {
                term: term.0,
                grant: 0,
            }
        } else {
            AuthorityEpoch {
                term: self.term,
                grant: self.grant.saturating_add(1),
            }
        }
    }

    /// 4-bit tag carried by every state update (enough to catch in-flight stale updates).
    pub fn tag(self) -> u8 {
        (self.grant.wrapping_add(self.term.wrapping_mul(7)) & 0xF) as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bumped_epochs_never_go_back() {
        let e = AuthorityEpoch {
            term: 3,
            grant: u32::MAX,
        };
        assert!(e.bumped(Term(3)) >= e);
        assert!(e.bumped(Term(4)) > e);
        assert!(e.bumped(Term(2)) >= e);
    }
}
