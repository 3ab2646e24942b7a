//! `host`'s and `join`'s voice and presence flags (`--voice-in`, `--voice-out`, `--name`, …).

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use softsync_bevy::voice::VoiceOptions;
use softsync_net::voice::RoutePolicy;
use softsync_voice::device::DeviceChoice;
use softsync_voice::processing::ProcessingConfig;
use softsync_voice::VoiceConfig;

/// How voice frames travel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum VoiceRoute {
    /// Relay through the host when a link to another member goes through TURN, else mesh.
    Auto,
    /// Directly to every member.
    Mesh,
    /// One copy to the host, which relays it.
    Relay,
}

/// Voice in the room.
#[derive(Args, Debug, Clone)]
pub struct VoiceOpts {
    /// Voice on without files: hear the room (nothing is played on a headless peer) and
    /// announce our state. --voice-in or --voice-out turn it on too.
    #[arg(long, help_heading = "Voice")]
    pub voice: bool,
    /// Say this WAV file into the room (any rate and channels; 48 kHz mono Opus on the wire):
    /// a bot's voice, for tests and benchmarks.
    #[arg(long, value_name = "FILE", help_heading = "Voice")]
    pub voice_in: Option<PathBuf>,
    /// Seconds after joining before --voice-in is first said.
    #[arg(long, value_name = "S", default_value_t = 1.0, value_parser = super::values::seconds, help_heading = "Voice")]
    pub voice_after: f64,
    /// Say --voice-in again every S seconds from each start (0: once).
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = super::values::seconds, help_heading = "Voice")]
    pub voice_every: f64,
    /// Write what this peer plays into DIR: mix.wav (stereo, each speaker placed at their
    /// head), peer-ID.wav (each speaker alone) and voice.json (the room time of the first
    /// sample).
    #[arg(long, value_name = "DIR", help_heading = "Voice")]
    pub voice_out: Option<PathBuf>,
    /// How our frames travel.
    #[arg(long, value_enum, default_value = "auto", help_heading = "Voice")]
    pub voice_route: VoiceRoute,
    /// The Opus bitrate with no loss, kilobits a second (8-40; loss reports raise it a
    /// quarter for FEC, the uplink budget caps it).
    #[arg(long, value_name = "KBPS", default_value_t = 24.0, value_parser = super::values::positive::<40>, help_heading = "Voice")]
    pub voice_kbps: f64,
    /// Start with the microphone muted.
    #[arg(long, help_heading = "Voice")]
    pub mute: bool,
    /// Play each speaker as soon as the jitter buffer allows, not held back to the delay its
    /// avatar is shown at.
    #[arg(long, help_heading = "Voice")]
    pub no_lip_sync: bool,
    /// Our head rises with our voice (a bot's mouth; the voice bench sees lip-sync by it).
    #[arg(long, help_heading = "Voice")]
    pub voice_nod: bool,
    /// The sound device for both sides: `default` (the system's), a name or part of one as
    /// `softsync audio-devices` lists it, or `none`. Desktop and VR peers use `default`
    /// unless told; headless peers open none. A device that is absent or fails gives a
    /// warning and a peer silent on that side, never an error.
    #[arg(long, value_name = "DEVICE", help_heading = "Voice")]
    pub voice_device: Option<String>,
    /// The microphone alone (overrides --voice-device).
    #[arg(long, value_name = "DEVICE", help_heading = "Voice")]
    pub voice_input_device: Option<String>,
    /// The loudspeaker or headset alone (overrides --voice-device).
    #[arg(long, value_name = "DEVICE", help_heading = "Voice")]
    pub voice_output_device: Option<String>,
    /// No acoustic echo cancellation on the microphone (on by default when a device both
    /// captures and plays; a headset needs none).
    #[arg(long, help_heading = "Voice")]
    pub no_echo_cancel: bool,
    /// No noise suppression on the microphone.
    #[arg(long, help_heading = "Voice")]
    pub no_noise_suppress: bool,
    /// No automatic gain control on the microphone.
    #[arg(long, help_heading = "Voice")]
    pub no_gain_control: bool,
    /// Send voice only while the talk key is held: V on a desktop peer; in VR the left
    /// controller's Y (Touch), B (Index) or menu (Vive, Windows MR) button.
    #[arg(long, help_heading = "Voice")]
    pub push_to_talk: bool,
    /// Our name, shown above our head on the others' desktop peers (at most 32 characters).
    #[arg(long, value_name = "NAME", value_parser = name, help_heading = "Voice")]
    pub name: Option<String>,
    /// Our avatar's colour, as hex RRGGBB (default: one from our peer id).
    #[arg(long, value_name = "RRGGBB", value_parser = colour, requires = "name", help_heading = "Voice")]
    pub colour: Option<[u8; 3]>,
}

fn name(v: &str) -> Result<String, String> {
    let p = softsync_peer::messages::Presence {
        name: v.to_owned(),
        colour: [0; 3],
    }
    .sanitized();
    if p.name.is_empty() {
        return Err(format!("{v:?} has no printable characters"));
    }
    if v.chars().count() > softsync_peer::messages::Presence::MAX_NAME {
        return Err(format!(
            "{v:?} is longer than {} characters",
            softsync_peer::messages::Presence::MAX_NAME
        ));
    }
    Ok(p.name)
}

fn colour(v: &str) -> Result<[u8; 3], String> {
    let h = v.trim_start_matches('#');
    let byte = |i: usize| {
        h.get(i..i + 2)
            .and_then(|b| u8::from_str_radix(b, 16).ok())
            .ok_or_else(|| format!("{v:?} is not a colour RRGGBB (e.g. e03c8a)"))
    };
    if h.len() != 6 {
        return Err(format!("{v:?} is not a colour RRGGBB (e.g. e03c8a)"));
    }
    Ok([byte(0)?, byte(2)?, byte(4)?])
}

impl VoiceOpts {
    /// Our presence, if we have a name: the colour given, or one from `peer`'s id later
    /// (`[0, 0, 0]` stands for "from the id" until the peer id is known).
    pub fn presence(&self) -> Option<softsync_peer::messages::Presence> {
        Some(softsync_peer::messages::Presence {
            name: self.name.clone()?,
            colour: self.colour.unwrap_or([0, 0, 0]),
        })
    }

    /// The devices asked for, `(input, output)`, on a peer that has a sound card to offer
    /// (`device_peer`: desktop and VR) or not.
    fn devices(&self, device_peer: bool) -> (Option<DeviceChoice>, Option<DeviceChoice>) {
        let pick = |side: &Option<String>| -> Option<DeviceChoice> {
            match side.as_deref().or(self.voice_device.as_deref()) {
                Some("none") => None,
                Some(d) => Some(DeviceChoice::parse(d)),
                None => device_peer.then_some(DeviceChoice::Default),
            }
        };
        (
            pick(&self.voice_input_device),
            pick(&self.voice_output_device),
        )
    }

    /// Whether the flags ask for voice at all.
    fn wanted(&self) -> bool {
        self.voice
            || self.voice_in.is_some()
            || self.voice_out.is_some()
            || self.push_to_talk
            || [
                &self.voice_device,
                &self.voice_input_device,
                &self.voice_output_device,
            ]
            .iter()
            .any(|d| d.as_deref().is_some_and(|d| d != "none"))
    }

    /// The room's voice options, if voice is on; `device_peer`: a desktop or VR peer.
    pub fn options(&self, device_peer: bool) -> Option<VoiceOptions> {
        if !self.wanted() {
            return None;
        }
        let (input_device, output_device) = self.devices(device_peer);
        Some(VoiceOptions {
            input_device,
            output_device,
            processing: ProcessingConfig {
                echo_cancel: !self.no_echo_cancel,
                noise_suppress: !self.no_noise_suppress,
                gain_control: !self.no_gain_control,
                ..ProcessingConfig::default()
            },
            push_to_talk: self.push_to_talk,
            input: self.voice_in.clone(),
            say_after: self.voice_after,
            say_every: self.voice_every,
            output: self.voice_out.clone(),
            route: match self.voice_route {
                VoiceRoute::Auto => RoutePolicy::Auto,
                VoiceRoute::Mesh => RoutePolicy::Mesh,
                VoiceRoute::Relay => RoutePolicy::Relay,
            },
            muted: self.mute,
            config: VoiceConfig {
                bitrate: (self.voice_kbps.clamp(8.0, 40.0) * 1000.0) as i32,
                lip_sync: !self.no_lip_sync,
                ..VoiceConfig::default()
            },
            nod: self.voice_nod,
        })
    }
}
