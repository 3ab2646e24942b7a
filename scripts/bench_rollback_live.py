"""The body of scripts/bench-rollback-live (run inside its network namespace)."""
import argparse
import os
import re
import statistics
import subprocess
import sys
import time

BIN = "target/release/softsync"
OUT = "docs/results/rollback"
TICK = os.sysconf("SC_CLK_TCK")


def cpu_s(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            parts = f.read().rsplit(")", 1)[1].split()
        return (int(parts[11]) + int(parts[12])) / TICK
    except OSError:
        return None


class Proc:
    def __init__(self, name, args, logdir):
        self.path = os.path.join(logdir, name + ".log")
        self.log = open(self.path, "w")
        self.p = subprocess.Popen([BIN] + args, stdout=self.log, stderr=subprocess.STDOUT)

    def text(self):
        with open(self.path) as f:
            return f.read()

    def wait_for(self, pattern, within):
        end = time.time() + within
        while time.time() < end:
            m = re.search(pattern, self.text())
            if m:
                return m
            if self.p.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError(f"{self.path}: no {pattern!r} within {within}s:\n{self.text()[-2000:]}")


def run(mode, peers, lat, seconds, logdir):
    room = f"{mode}{peers}l{lat}"
    cond = f"lat={lat}ms,jitter={lat // 10}ms,loss=5%,seed=7"
    common = ["--room", room, "--duration", str(seconds + 30), "--net-condition", cond]
    if mode == "rollback":
        common += ["--sync", "rollback"]
    # peer k starts with the scene's object 2k+1, as in the in-process bench
    host = Proc(f"{room}-host", ["host", "--bind", "127.0.0.1:0", "--bot", "throw:1"] + common, logdir)
    url = host.wait_for(r"signaling on (\S+)", 20).group(1)
    procs = [host]
    for k in range(1, peers):
        procs.append(Proc(f"{room}-j{k}", ["join", "--signal", url, "--bot", f"throw:{2 * k + 1}"] + common, logdir))
    ready = rf"epoch n=\d+ frame=\d+ players=(\d+,){{{peers - 1}}}\d+" if mode == "rollback" else r"joined"
    for p in procs[1:]:
        p.wait_for(ready, 40)
    if mode == "rollback":
        host.wait_for(ready, 20)
    time.sleep(2)
    marks = [len(p.text()) for p in procs]
    cpu0 = [cpu_s(p.p.pid) for p in procs]
    t0 = time.time()
    time.sleep(seconds)
    dt = time.time() - t0
    cpu1 = [cpu_s(p.p.pid) for p in procs]
    window = [p.text()[m:] for p, m in zip(procs, marks)]
    for p in procs:
        p.p.terminate()
    for p in procs:
        try:
            p.p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.p.kill()
    ups, resim, frame_p95, desyncs = [], [], [], 0
    for p, w in zip(procs, window):
        rates = [float(x) for x in re.findall(r"\bup=(\d+(?:\.\d+)?)B/s", w)]
        if rates:
            ups.append(statistics.mean(rates))
        if mode == "rollback":
            r = [int(x) for x in re.findall(r"resimulated=(\d+)", w)]
            if len(r) >= 2:
                resim.append((r[-1] - r[0]) / max(len(r) - 1, 1))
            s = re.search(r"rollback\.summary .*frame_ms_p95=([\d.]+)", p.text())
            if s:
                frame_p95.append(float(s.group(1)))
            desyncs += len(re.findall(r"^desync frame=", p.text(), re.M))
    cpu = [100.0 * (b - a) / dt for a, b in zip(cpu0, cpu1) if a is not None and b is not None]
    return {
        "mode": mode,
        "peers": peers,
        "lat_ms": lat,
        "bytes_per_s": statistics.mean(ups) if ups else float("nan"),
        "cpu_pct": statistics.mean(cpu) if cpu else float("nan"),
        "rollback_frames_per_s": statistics.mean(resim) if resim else 0.0,
        "frame_ms_p95": max(frame_p95) if frame_p95 else float("nan"),
        "desyncs": desyncs,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=15)
    ap.add_argument("--peers", default="2,4")
    ap.add_argument("--lat", default="0,50,150")
    a = ap.parse_args()
    logdir = "/tmp/softsync-bench-rollback-live"
    os.makedirs(logdir, exist_ok=True)
    os.makedirs(OUT, exist_ok=True)
    rows = []
    for peers in [int(x) for x in a.peers.split(",")]:
        for lat in [int(x) for x in a.lat.split(",")]:
            for mode in ["state", "rollback"]:
                r = run(mode, peers, lat, int(a.seconds), logdir)
                name = "rollback.live" if mode == "rollback" else "statesync.live"
                extra = (
                    f" rollback_frames_per_s={r['rollback_frames_per_s']:.1f} frame_ms_p95={r['frame_ms_p95']:.2f}"
                    if mode == "rollback"
                    else ""
                )
                print(
                    f"RESULT {name} peers={peers} lat_ms={lat} loss_pct=5 bytes_per_s={r['bytes_per_s']:.0f} "
                    f"cpu_pct={r['cpu_pct']:.1f}{extra} desyncs={r['desyncs']}",
                    flush=True,
                )
                rows.append(r)
    cols = ["mode", "peers", "lat_ms", "bytes_per_s", "cpu_pct", "rollback_frames_per_s", "frame_ms_p95", "desyncs"]
    with open(os.path.join(OUT, "live.csv"), "w") as f:
        f.write(",".join(cols) + "\n")
        for r in rows:
            f.write(",".join(f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + "\n")
    with open(os.path.join(OUT, "live.md"), "w") as f:
        f.write(
            "# Rollback against state sync, real processes (generated by `scripts/bench-rollback-live`)\n\n"
            "Each peer a `softsync` process with `--bot throw` on WebRTC in one network namespace, its links "
            "behind the seeded conditioner (one-way latency, 5 % loss); every process on this machine's 2 cores. "
            "Bytes: datagram payload per process per second; CPU: per process; frame ms: rollback's tick "
            "(advance, re-simulation, saves), p95 of the worst process (a state-sync process does not time "
            "its simulation apart from its frame: its cost per frame is in rooms.md).\n\n"
            "| mode | peers | latency ms | bytes/s per peer | CPU % per peer | re-simulated frames/s | frame ms p95 | desyncs |\n"
            "|---|---|---|---|---|---|---|---|\n"
        )
        for r in rows:
            f.write(
                f"| {r['mode']} | {r['peers']} | {r['lat_ms']} | {r['bytes_per_s']:.0f} | {r['cpu_pct']:.1f} | "
                f"{r['rollback_frames_per_s']:.1f} | "
                + (f"{r['frame_ms_p95']:.2f}" if r["mode"] == "rollback" else "—")
                + f" | {r['desyncs']} |\n"
            )
    print(f"wrote {OUT}/live.csv and live.md")


if __name__ == "__main__":
    sys.exit(main())
