//! `softsync-net`: the sans-IO network core of softsync.
//!
//! One [`Session`] per local peer is a state machine in the style of quinn-proto: datagrams
//! and `now` go in, datagrams, events and the next timeout come out. It implements the
//! thesis's host model (chapter 5): a host relays between clients and is a client of itself,
//! every object has exactly one owner, authority moves on request, transforms and soft-body
//! particles are replicated under per-class send policies, packed into MTU-sized datagrams and
//! interpolated on remote peers; when the host goes, the earliest joiner takes over.
//!
//! No sockets, no clock, no randomness inside: time and seeds are arguments.
//!
//! Feature `testing` (off by default; the crate's own tests and examples turn it on):
//! the in-memory transport (`transport::memory`), the N-peer virtual-time harness
//! (`harness`), fuzzing entry points (`fuzzing`) and `Session::send_raw_control`.

pub mod bits;
pub mod door;
pub mod error;
#[cfg(feature = "testing")]
pub mod fuzzing;
#[cfg(feature = "testing")]
pub mod harness;
pub mod ids;
pub mod interp;
pub mod messages;
pub mod policy;
pub mod quant;
pub mod reliable;
pub mod rng;
pub mod session;
pub mod share;
pub mod stats;
pub mod time;
pub mod transport;
pub mod voice;
pub mod wire;

pub use error::NetError;
pub use ids::{AuthorityEpoch, ClassId, NetId, PeerId, Term};
pub use interp::InterpolationConfig;
pub use policy::{
    AuthorityPolicy, ClassConfig, FailureDetector, MessageConfig, PeerBudget, SendPolicy,
    SessionConfig, SoftBodyMode, StateRoute,
};
pub use session::{
    DisplayedState, Event, KeptObject, KickError, ObjectState, RoomImage, RoomKey, Session,
};
pub use stats::Stats;
pub use time::Instant;
#[cfg(feature = "testing")]
pub use transport::MemoryHub;
pub use transport::{ConditionerConfig, LinkConditioner, PeerEvent, Transmit, Transport};
pub use wire::{
    Delivery, MessageKind, MessageRefusal, MessageTarget, ReceivedMessage, PROTOCOL_VERSION,
};
