//! What a peer reports: the stats line (the dump is `softsync_peer::dump`).

use std::time::Duration;

use softsync_net::stats::Traffic;
use softsync_net::Instant;
use softsync_peer::Peer;

/// The mean round-trip time over this peer's links, milliseconds (None before any probe).
pub fn mean_rtt_ms(peer: &Peer) -> Option<f64> {
    let rtts: Vec<f64> = peer
        .session()
        .stats()
        .links
        .values()
        .filter_map(|l| l.rtt)
        .map(|r| r.as_secs_f64() * 1e3)
        .collect();
    (!rtts.is_empty()).then(|| rtts.iter().sum::<f64>() / rtts.len() as f64)
}

/// Rates between two stats readings.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rates {
    /// Bytes/s sent.
    pub up: f64,
    /// Bytes/s received.
    pub down: f64,
    /// Datagrams/s sent.
    pub up_packets: f64,
    /// Datagrams/s received.
    pub down_packets: f64,
}

/// Remembers the previous reading for rates, and the frames since.
#[derive(Clone, Debug, Default)]
pub struct StatsLine {
    last: Option<(softsync_net::Instant, Traffic, Traffic)>,
    last_frame: Option<Instant>,
    /// Intervals between frames since the last line.
    frames: Vec<Duration>,
}

impl StatsLine {
    /// A frame ran at `now` (the line shows the median and longest interval).
    pub fn frame(&mut self, now: Instant) {
        if let Some(t) = self.last_frame {
            self.frames.push(now.saturating_since(t));
        }
        self.last_frame = Some(now);
    }

    /// The stats line of `peer` at `now` (and the rates it shows).
    pub fn line(&mut self, now: Instant, peer: &Peer) -> (String, Rates) {
        let session = peer.session();
        let st = session.stats();
        let rates = match self.last {
            Some((t, up, down)) => {
                let dt = now.saturating_since(t).max(Duration::from_millis(1));
                let (up, up_packets) = st.up.rate_since(&up, dt);
                let (down, down_packets) = st.down.rate_since(&down, dt);
                Rates {
                    up,
                    down,
                    up_packets,
                    down_packets,
                }
            }
            None => Rates::default(),
        };
        self.last = Some((now, st.up, st.down));
        let rtt = mean_rtt_ms(peer).map_or("-".to_owned(), |r| format!("{r:.2}ms"));
        // a partition's beacons (session::heal), once there are any
        let heal = if st.beacons_sent + st.beacons_heard > 0 {
            format!(
                " beacons={}/{} merges={}",
                st.beacons_sent, st.beacons_heard, st.merges
            )
        } else {
            String::new()
        };
        // each link's RTT (ms), and this peer's frame intervals since the last line
        let rtts: Vec<String> = st
            .links
            .iter()
            .filter_map(|(p, l)| Some(format!("{}:{:.1}", p.0, l.rtt?.as_secs_f64() * 1e3)))
            .collect();
        let frames = {
            let f = &mut self.frames;
            f.sort_unstable();
            let ms = |d: Option<&Duration>| d.map_or(0.0, |d| d.as_secs_f64() * 1e3);
            let line = format!(
                " frame_ms={:.1}/{:.1}",
                ms(f.get(f.len() / 2)),
                ms(f.last())
            );
            f.clear();
            if rtts.is_empty() {
                line
            } else {
                format!("{line} rtts={}", rtts.join(","))
            }
        };
        let line = format!(
            "stats t={:.1}s peer={} host={} term={} peers={} up={:.0}B/s down={:.0}B/s datagrams={:.0}/{:.0}/s rtt={} owned={}/{}{frames}{heal}",
            now.as_secs_f64(),
            peer.me().0,
            session.host_id().map_or("-".into(), |h| h.0.to_string()),
            session.term().0,
            session.members().len(),
            rates.up,
            rates.down,
            rates.up_packets,
            rates.down_packets,
            rtt,
            peer.owned_count(),
            peer.objects().len(),
        );
        (line, rates)
    }
}
