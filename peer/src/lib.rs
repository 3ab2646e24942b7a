//! `softsync-peer`: one peer of a softsync room, engine-agnostic and sans-IO.
