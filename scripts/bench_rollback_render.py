"""The body of scripts/bench-rollback-render (run inside its network namespace)."""
import argparse
import os
import re
import statistics
import subprocess
import tempfile
import time

from benchproc import Proc

BIN = "target/debug/softsync"
OUT = "docs/results/rollback"


def xvfb(logdir):
    for n in range(20):
        num = 300 + (os.getpid() + n * 7) % 400
        if os.path.exists(f"/tmp/.X11-unix/X{num}") or os.path.exists(f"/tmp/.X{num}-lock"):
            continue
        x = subprocess.Popen(["Xvfb", f":{num}", "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                             stdout=subprocess.DEVNULL, stderr=open(os.path.join(logdir, "xvfb.log"), "w"))
        for _ in range(200):
            if os.path.exists(f"/tmp/.X11-unix/X{num}"):
                return x, f":{num}"
            if x.poll() is not None:
                break
            time.sleep(0.05)
        x.kill()
    raise RuntimeError("no Xvfb display came up")


def field(line, key):
    m = re.search(rf"\b{key}=(\S+)", line)
    return m.group(1) if m else None


def run(front, lat, seconds, logdir, display):
    room = f"render-{front}"
    cond = f"lat={lat}ms,jitter={lat // 10}ms,loss=5%,seed=7"
    common = ["--room", room, "--sync", "rollback", "--net-condition", cond, "--quiet"]
    host = Proc(BIN, f"{room}-host", ["host", "--bind", "127.0.0.1:0", "--bot", "throw:3",
                                 "--duration", str(seconds + 60)] + common, logdir)
    url = host.wait_for(r"signaling on (\S+)", 20).group(1)
    args = ["join", "--signal", url, "--duration", str(seconds + 40)] + common
    env = None
    if front == "desktop":
        args += ["--desktop", "--window", "640x480", "--focus", "softbox", "--screenshot-dir",
                 os.path.join(logdir, "shots"), "--screenshot-every", "1", "--screenshots", "1000"]
        env = dict(os.environ, DISPLAY=display, WGPU_BACKEND="vulkan",
                   VK_ICD_FILENAMES="/usr/share/vulkan/icd.d/lvp_icd.x86_64.json")
    else:
        args += ["--bot", "idle"]
    joiner = Proc(BIN, f"{room}-joiner", args, logdir, env)
    joiner.wait_for(r"epoch n=\d+ frame=\d+ players=\d+,\d+", 90)
    time.sleep(seconds)
    joiner.stop()
    host.stop()
    text = joiner.text()
    summary = [l for l in text.splitlines() if l.startswith("rollback.summary")]
    if not summary:
        raise RuntimeError(f"{joiner.path}: no summary:\n{text[-2000:]}")
    s = summary[-1]
    draws = [float(field(l, "draw_us_p50")) for l in text.splitlines()
             if l.startswith("screenshot ") and field(l, "draw_us_p50")]
    return {
        "front": front,
        "lat_ms": lat,
        "frames": int(field(s, "frames")),
        "rollbacks": int(field(s, "rollbacks")),
        "frame_ms_p95": float(field(s, "frame_ms_p95")),
        "frame_ms_p99": float(field(s, "frame_ms_p99")),
        "corrections": int(field(s, "corrections")),
        "correction_mm_p95": float(field(s, "correction_mm_p95")),
        "desyncs": int(field(s, "desyncs")),
        "draw_us_p50": statistics.median(draws) if draws else float("nan"),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=int, default=40)
    ap.add_argument("--lat", type=int, default=50)
    a = ap.parse_args()
    logdir = tempfile.mkdtemp(prefix="softsync-bench-rollback-render-")
    x, display = xvfb(logdir)
    rows = []
    try:
        for front in ["headless", "desktop"]:
            rows.append(run(front, a.lat, a.seconds, logdir, display))
            print(rows[-1], flush=True)
    finally:
        x.kill()
    os.makedirs(OUT, exist_ok=True)
    keys = list(rows[0].keys())
    with open(os.path.join(OUT, "render.csv"), "w") as f:
        f.write(",".join(keys) + "\n")
        for r in rows:
            f.write(",".join(str(r[k]) for k in keys) + "\n")
    h, d = rows
    lines = [
        f"RESULT rollback.render peers=2 lat_ms={a.lat} sim_frame_p99_ms={d['frame_ms_p99']:.2f} "
        f"sim_frame_p95_ms={d['frame_ms_p95']:.2f} headless_sim_frame_p99_ms={h['frame_ms_p99']:.2f} "
        f"correction_p95_mm={d['correction_mm_p95']:.1f} corrections={d['corrections']} "
        f"rollbacks={d['rollbacks']} draw_us_p50={d['draw_us_p50']:.0f} desyncs={d['desyncs']} "
        f"seconds={a.seconds}",
    ]
    with open(os.path.join(OUT, "render.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    for l in lines:
        print(l)
    print(f"logs in {logdir}")


if __name__ == "__main__":
    main()
