//! The command line's value parsers: each says what a good value is.

use std::net::SocketAddr;

use softsync_net::ConditionerConfig;

use super::parse_condition;

/// `--state-route`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum Route {
    /// Through the host.
    Relay,
    /// From each owner to every member.
    Direct,
}

/// `--sync`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(super) enum SyncArg {
    /// Owners simulate and send state.
    State,
    /// Everyone simulates from everyone's inputs (ggrs).
    Rollback,
}

pub(super) fn seconds(v: &str) -> Result<f64, String> {
    match v.parse::<f64>() {
        Ok(s) if s.is_finite() && (0.0..1e7).contains(&s) => Ok(s),
        _ => Err(format!("{v:?} is not a number of seconds")),
    }
}

pub(super) fn positive<const MAX: u32>(v: &str) -> Result<f64, String> {
    match v.parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 && s <= f64::from(MAX) => Ok(s),
        _ => Err(format!("{v:?} must be a number in (0, {MAX}]")),
    }
}

pub(super) fn address(v: &str) -> Result<SocketAddr, String> {
    v.parse()
        .map_err(|_| format!("{v:?} is not an address like 127.0.0.1:3536"))
}

/// One `ws://` or `wss://` URL, or several separated by commas (tried in order).
pub(super) fn ws_url(v: &str) -> Result<String, String> {
    for u in v.split(',').map(str::trim) {
        if !(u.starts_with("ws://") || u.starts_with("wss://")) {
            return Err(format!("{u:?} is not a ws:// or wss:// URL"));
        }
    }
    Ok(v.to_owned())
}

pub(super) fn token(v: &str) -> Result<softsync_net::wire::RoomToken, String> {
    v.parse()
}

pub(super) fn room_name(v: &str) -> Result<String, String> {
    if softsync_net_matchbox::valid_room_name(v) {
        Ok(v.to_owned())
    } else {
        Err(format!(
            "{v:?} is not a room name (1-64 characters of A-Z a-z 0-9 - _ .)"
        ))
    }
}

pub(super) fn threshold_mm(v: &str) -> Result<f32, String> {
    match v.parse::<f32>() {
        Ok(x) if x.is_finite() && (0.0..=1000.0).contains(&x) => Ok(x),
        _ => Err(format!("{v:?} must be 0-1000")),
    }
}

pub(super) fn window_size(v: &str) -> Result<(u32, u32), String> {
    match v
        .split_once('x')
        .map(|(a, b)| (a.parse::<u32>(), b.parse::<u32>()))
    {
        Some((Ok(a), Ok(b))) if (64..=8192).contains(&a) && (64..=8192).contains(&b) => Ok((a, b)),
        _ => Err(format!("{v:?} is not WIDTHxHEIGHT (64-8192)")),
    }
}

pub(super) fn condition(v: &str) -> Result<ConditionerConfig, String> {
    parse_condition(v).map_err(|e| e.0)
}
