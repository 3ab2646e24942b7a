//! The generational handle of a soft body: a leaf, so the error type can name it without
//! depending on the set.

/// Generational handle of a soft body in a [`SoftBodySet`](crate::SoftBodySet).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SoftBodyHandle {
    /// Slot in the set.
    pub(super) index: u32,
    /// How often the slot was reused: a handle of a removed body never resolves again.
    pub(super) generation: u32,
}
