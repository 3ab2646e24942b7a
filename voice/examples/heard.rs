//! `cargo run -p softsync-voice --example heard -- SAID.wav SAID_ROOM_MS DIR SPEAKER`: mouth
//! to ear and similarity of one saying in a listener's `--voice-out` folder.
#![allow(clippy::unwrap_used)]
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let said = softsync_voice::files::read_wav(std::path::Path::new(&a[1])).unwrap();
    let h = softsync_voice::analysis::heard_in(
        &said,
        a[2].parse().unwrap(),
        std::path::Path::new(&a[3]),
        a[4].parse().unwrap(),
        1000.0,
    )
    .unwrap();
    println!("{h:?}");
}
