//! Rollback rooms (issue 15): every peer simulates the whole room from everyone's inputs,
//! predicts the inputs it does not have yet, and re-simulates when they come (GGPO, through
//! `ggrs`); one's own hands act at once, with no trip to an owner and back. The thesis (5.2)
//! tried input sync, measured 63 ms from grip to pick-up, and went to owner-simulates state
//! sync; with a deterministic world and saved states a peer does not wait for anyone.
//!
//! - [`input`]: a player's frame of input (head and hands, grip, trigger), quantized.
//! - [`world`]: the deterministic world (scene, soft bodies, every player's hands), its saved
//!   state for ggrs, its checksum and the portable snapshot a membership change starts from.
//! - [`socket`]: ggrs's messages and the snapshot on the room's transport.
//! - [`room`]: a rollback peer: the session keeps membership (the host model), each
//!   membership change starts the next ggrs session (an *epoch*) from an agreed frame.

pub mod input;
pub mod room;
pub mod script;
pub mod socket;
pub mod world;

pub use input::{PartInput, PlayerInput};
pub use room::{Correction, Epoch, RollbackConfig, RollbackEvent, RollbackPeer, RollbackStats};
pub use world::{RollbackWorld, Snapshot, WorldError, WorldState};

/// ggrs's compile-time configuration for a softsync room.
#[derive(Debug)]
pub struct GgrsConfig;

impl ggrs::Config for GgrsConfig {
    type Input = PlayerInput;
    type InputPredictor = ggrs::PredictRepeatLast;
    /// Shared: ggrs keeps it for rollback, the room for the next epoch's snapshot.
    type State = std::rc::Rc<WorldState>;
    type Address = softsync_net::PeerId;
}
