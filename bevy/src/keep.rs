//! A room kept in a store ([`RoomOptions::store`](crate::RoomOptions::store)): the keeper is
//! the peer library's ([`softsync_store::keeper`]); here the host opens its store before it
//! connects, so a store that will not open fails the room's opening with the reason.

use softsync_net::{RoomImage, SessionConfig};
use softsync_peer::Scene;
use softsync_store::keeper::{open_store, Keeper, StoreOptions};

use crate::room::OpenError;

/// The store for a host: opened, checked against the scene, the kept room if any.
pub(crate) fn host_store(
    opts: &StoreOptions,
    scene: &Scene,
    cfg: &SessionConfig,
) -> Result<(Keeper, Option<RoomImage>), OpenError> {
    let (writer, kept) = open_store(opts, scene, cfg).map_err(OpenError::Config)?;
    Ok((Keeper::hosting(opts.clone(), writer), kept))
}
