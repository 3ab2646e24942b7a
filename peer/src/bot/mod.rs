//! Bots: a small script language for avatar motion and actions, so that tests and load runs
//! are reproducible.
//!
//! One command per line or separated by `;`, `#` starts a comment. HAND is `left`, `right` or
//! `head`; times are seconds; positions metres in the room (y up, table top at 0.75 m).
//!
//! ```text
//! wait S                        do nothing for S
//! move HAND X Y Z [in S]        go to a point (straight line over S, default 0.5)
//! offset HAND DX DY DZ [in S]   go by an offset
//! reach HAND TARGET [at DX DY DZ] [in S]
//!                               go to an object: a class of the scene (the thesis room's:
//!                               bunny, softball, softbox, plate, block, can, ball) or
//!                               `nearest`; soft bodies are reached at their particle nearest
//!                               to the hand, or with `at` nearest to the object's center +
//!                               (DX DY DZ) (room axes: two bots take opposite sides)
//! grab HAND [timeout S]         close the grip; waits until held (through the authority
//!                               request if another peer owns it), or gives up (default 3 s)
//! squeeze HAND DEPTH [in S]     push the held point DEPTH metres toward the body's center
//! pull HAND DX DY DZ [in S]     move the held point by an offset (as `offset`, but says so
//!                               when the hand holds nothing); on a body another peer
//!                               simulates the hand is a remote hand (co-manipulation)
//! release HAND                  open the grip
//! wave HAND AMPLITUDE PERIOD S  move sinusoidally (load runs); HAND may be `all` (head
//!                               and both hands at once, out of phase)
//! own TARGET [timeout S]        ask for authority over the object (nearest of its kind to
//!                               the right hand) and wait until ours (default 3 s)
//! tear HAND TARGET DX DY DZ [DX DY DZ]… [in S]
//!                               a scalpel in HAND goes through the points (offsets from
//!                               TARGET's center when the stroke starts, room axes), S per
//!                               step (default 0.15); each step tears TARGET from the
//!                               last point to this one, the blade upright 4 cm above the
//!                               tip; the stroke ends with a lift (TARGET ours, or another
//!                               peer's: its owner applies the stroke as its own)
//! cut TARGET NX NY NZ           cut TARGET through its center, plane normal N (room; ours, or
//!                               another peer's through its owner)
//! slice HAND TARGET DX DY DZ DX DY DZ [in S]
//!                               the cut gesture: HAND's tool becomes the cutter and sweeps,
//!                               trigger held, from TARGET's center + the first offset to
//!                               its center + the second over S (default 0.5), the blade
//!                               upright; the body is cut by the plane of the sweep (tear
//!                               paper §3.2, `peer/cutter.rs`); then the tool is the
//!                               scalpel again
//! say TEXT                      send TEXT to everyone in the room (a reliable
//!                               [`Say`](crate::messages::Say) message; at most 200 bytes)
//! note TEXT                     as `say`, retained: the room keeps the latest note (a late
//!                               joiner gets it; a kept room keeps it between sessions)
//! replay pause|play|seek S|speed X   a spectator of a played-back recording steers it
//!                               (`softsync replay --serve`: a `ReplayControl` to the host)
//! kick PEER [REASON]            the host kicks PEER out and bans it for the room's life
//!                               (`Session::kick`); PEER is an id as the peer printed it
//!                               (decimal, or hex with 0x) or `newest` (the member that
//!                               joined last); REASON at most 120 bytes
//! loop                          start again from the top (last line)
//! ```
//!
//! On a peer with a tracked device (`--vr`, `--desktop`), a script runs on top of it: tracked
//! parts follow the device, displaced by the script's motion (`move` and `reach` still go to
//! room positions), and the grip is the larger of the script's and the device's.
//!
//! Built-in scripts by name: `squeeze` (reach the soft ball, grab, squeeze, release, back),
//! `idle` (stand still), `wave` (both hands waving, forever).
//!
//! A bot says what it does (`reach softbox (object 5)`, `grabbed object 5 after 120 ms`, …);
//! the driver takes those lines with [`Bot::poll_message`] after each step and logs them.
//!
//! The language is `parse.rs`, the interpreter `run.rs`; what a script acts on is a
//! [`BotWorld`] (`world.rs`): a state-sync [`Peer`](crate::Peer), or a rollback room's player
//! (`softsync-bevy`'s `rollback.rs`: there a `tear` holds the scalpel's trigger along its
//! path and the room tears where the blade goes, `slice` sweeps the cutter, `cut`, `own` and
//! `kick` say why they do not apply, and `say` sends the room a message).

mod parse;
mod run;
mod world;

pub use parse::{builtin, parse, Cmd, ScriptError};
pub use run::Bot;
pub use world::BotWorld;

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use glam::Vec3;

    #[test]
    fn scripts_parse_and_errors_name_the_command() {
        let c = parse("wait 1; reach right softball in 1\n# comment\ngrab right; squeeze right 0.03 in 0.6; release right; loop").unwrap();
        assert_eq!(c.len(), 6);
        assert_eq!(c[1], Cmd::Reach(2, Some("softball".into()), None, 1.0));
        assert_eq!(c[2], Cmd::Grab(2, 3.0));
        let c = parse("reach left bunny at -0.1 0 0 in 0.8; pull left -0.05 0 0.01 in 1").unwrap();
        assert_eq!(
            c,
            [
                Cmd::Reach(
                    1,
                    Some("bunny".into()),
                    Some(Vec3::new(-0.1, 0.0, 0.0)),
                    0.8
                ),
                Cmd::Pull(1, Vec3::new(-0.05, 0.0, 0.01), 1.0)
            ]
        );
        assert!(parse("reach left bunny at 1 2").is_err());
        assert!(parse("pull head 0 0 1").is_err());
        for name in ["squeeze", "idle", "wave"] {
            parse(builtin(name).unwrap()).unwrap();
        }
        let e = parse("wait 1; jump right").unwrap_err();
        assert_eq!(e.index, 2);
        assert!(e.to_string().contains("unknown command"), "{e}");
        assert!(parse("reach right tea/pot")
            .unwrap_err()
            .msg
            .contains("not a class name"));
        // A name the scene does not have: refused when the bot meets the scene.
        let scene = Scene::by_name(
            "thesis-room",
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets")),
        )
        .unwrap();
        let teapot = Bot::new(parse("reach right teapot; own bunny").unwrap());
        let e = teapot.check(&scene).unwrap_err();
        assert!(e.contains("teapot") && e.contains("softbox"), "{e}");
        Bot::new(parse("reach right softball; cut softbox 0 1 0").unwrap())
            .check(&scene)
            .unwrap();
        assert_eq!(
            parse("say  the valve is open ").unwrap(),
            [Cmd::Say("the valve is open".into(), false)]
        );
        assert!(parse("say").is_err());
        assert_eq!(
            parse("kick newest spam in the chat; kick 0x1f; kick 42 x").unwrap(),
            [
                Cmd::Kick(None, "spam in the chat".into()),
                Cmd::Kick(Some(31), String::new()),
                Cmd::Kick(Some(42), "x".into())
            ]
        );
        assert!(parse("kick").is_err());
        assert!(parse("kick someone").is_err());
        assert!(parse(&format!("kick newest {}", "x".repeat(121))).is_err());
        assert!(parse(&format!("say {}", "x".repeat(201))).is_err());
        assert!(parse("move left 1 2").is_err());
        assert!(parse("move left 1 2 NaN").is_err());
        assert!(parse("grab head").is_err());
        assert!(
            parse("wait 1 2").is_ok(),
            "extra words after wait are ignored"
        );
        assert!(parse("move left 0 1 0 in -1").is_err());
        let c =
            parse("own bunny; tear right bunny 0 1 0 0.01 1 0 0.02 1 0 in 0.1; cut softbox 0 1 0")
                .unwrap();
        assert_eq!(c[0], Cmd::Own(Some("bunny".into()), 3.0));
        assert!(
            matches!(&c[1], Cmd::Tear(2, Some(k), p, s) if k == "bunny" && p.len() == 3 && *s == 0.1)
        );
        assert_eq!(c[2], Cmd::Cut(Some("softbox".into()), Vec3::Y));
        assert!(
            parse("tear right bunny 0 1 0").is_err(),
            "one point is no segment"
        );
        assert!(parse("tear right bunny 0 1 0 1 1").is_err());
        assert!(parse("tear head bunny 0 1 0 1 1 1").is_err());
        assert!(parse("cut bunny 0 0 0").is_err());
        assert!(parse("cut bunny 0 NaN 1").is_err());
    }
}
