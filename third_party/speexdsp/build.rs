//! Link libspeexdsp from the system (pkg-config: `speexdsp`; Debian: `libspeexdsp-dev`).

fn main() {
    if let Err(e) = pkg_config::Config::new()
        .atleast_version("1.2")
        .probe("speexdsp")
    {
        panic!(
            "libspeexdsp (>= 1.2) not found by pkg-config: {e}\n\
             install it (Debian/Ubuntu: apt-get install libspeexdsp-dev); .ci/run does"
        );
    }
}
