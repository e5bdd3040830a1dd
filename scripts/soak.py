#!/usr/bin/env python3
"""The soak of scripts/soak.sh (run that: it sets up the namespaces). Standard library only.

Starts the simulator and `omnirow record`, injects the faults on a schedule, scrapes /healthz and
/metrics every second, samples RSS, fds and threads every 10 s, checks and deletes closed
recordings as they rotate (the tmpfs holds a few), and judges the run at the end.
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

SIM = "arv-fake-gv-camera-0.8"
SERIAL = "OMNIROWSOAK"


def parse_args():
    p = argparse.ArgumentParser()
    p.add_argument("--bin", required=True)
    p.add_argument("--duration", type=float, default=600.0, help="seconds of the node's run")
    p.add_argument("--kills", type=int, default=10, help="camera kills and restarts")
    p.add_argument("--loss", type=float, default=10.0, help="lost GVSP packets per thousand")
    p.add_argument("--fps", type=float, default=10.0, help="the camera's frame rate")
    p.add_argument("--down", type=float, default=3.0, help="seconds the camera stays dead")
    p.add_argument("--out", default="target/soak", help="logs and soak.json go here")
    p.add_argument("--disk-mb", type=int, default=1024, help="the recording tmpfs")
    p.add_argument("--port", type=int, default=18347)
    return p.parse_args()


def metrics(port):
    """The node's /metrics as {name{labels}: value}, or None."""
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=2) as r:
            text = r.read().decode()
    except Exception:
        return None
    out = {}
    for line in text.splitlines():
        if line and not line.startswith("#"):
            k, _, v = line.rpartition(" ")
            try:
                out[k] = float(v)
            except ValueError:
                pass
    return out


def healthz(port):
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=2) as r:
            return json.loads(r.read())
    except urllib.error.HTTPError as e:  # 503 carries the same JSON
        try:
            return json.loads(e.read())
        except Exception:
            return None
    except Exception:
        return None


def proc_sample(pid):
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        rss = next(int(l.split()[1]) for l in status.splitlines() if l.startswith("VmRSS:"))
        fds = len(os.listdir(f"/proc/{pid}/fd"))
        threads = len(os.listdir(f"/proc/{pid}/task"))
        return rss, fds, threads
    except (OSError, StopIteration):
        return None


def start_sim(loss):
    cmd = [SIM, "-i", "127.0.0.1", "-s", SERIAL]
    if loss > 0:
        cmd += ["-r", str(loss)]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def config(path, fps, rec_dir):
    path.write_text(
        f"""[source]
kind = "camera"

[gige]
camera = "{SERIAL}"
pixel_format = "BayerRG8"
roi = {{ x = 0, y = 0, width = 2448, height = 2048 }}
frame_rate = {fps}
pop_timeout_ms = 500
reconnect_initial_ms = 200
reconnect_max_ms = 1000
realtime = false

[gige.stream]
packet_size = 16000
socket_buffer = 8388608
packet_socket = false

[record]
dir = "{rec_dir}"
rotate_mb = 160
reserve_mb = 96
"""
    )


class Files:
    """Checks closed recordings as they rotate and deletes them (the tmpfs holds a few)."""

    def __init__(self, bin_, rec_dir):
        self.bin = bin_
        self.dir = rec_dir
        self.checked = []  # (name, frames, intact, problem)

    def check(self, path):
        r = subprocess.run(
            [self.bin, "recording", "check", "--json", str(path)],
            capture_output=True,
            text=True,
        )
        try:
            v = json.loads(r.stdout)
        except json.JSONDecodeError:
            v = {"error": r.stdout + r.stderr}
        ok = r.returncode == 0 and v.get("intact") is True
        self.checked.append((path.name, v.get("frames", 0), ok, None if ok else v))
        return ok

    def sweep(self, keep_newest=True):
        files = sorted(self.dir.glob("*.mcap"))
        for f in files[:-1] if keep_newest else files:
            self.check(f)
            if keep_newest:
                f.unlink()


def main():
    a = parse_args()
    out = Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    disk = out / "disk"
    disk.mkdir(exist_ok=True)
    tmpfs = False
    if os.environ.get("OMNIROW_SOAK_NS") and os.geteuid() == 0:
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={a.disk_mb}m", "tmpfs", str(disk)], check=True)
        tmpfs = True
    rec_dir = disk / "rec"
    cfg = out / "soak.toml"
    config(cfg, a.fps, rec_dir)
    log = open(out / "node.log", "w")
    sim = start_sim(a.loss)
    time.sleep(1.0)
    env = dict(os.environ, OMNIROW_LOG_FORMAT="json", RUST_LOG="info")
    node = subprocess.Popen(
        [a.bin, "record", "--out", str(rec_dir), "--no-print", "--http", f"127.0.0.1:{a.port}", "--config", str(cfg)],
        stdout=subprocess.DEVNULL,
        stderr=log,
        env=env,
    )
    files = Files(a.bin, rec_dir)
    warmup = min(60.0, a.duration * 0.2)
    tail = min(30.0, a.duration * 0.15)
    span = a.duration - warmup - tail
    kills = [warmup + span * (k + 0.5) / max(a.kills, 1) for k in range(a.kills)]
    fill_at = None
    if tmpfs:
        # Between the middle two kills, not on one.
        i = len(kills) // 2
        fill_at = (kills[i - 1] + kills[i]) / 2 if len(kills) >= 2 else warmup + span * 0.5
    samples = []  # (t, rss_kb, fds, threads, steady: streaming and recording)
    scrapes = []  # (t, frames_in, state, alive, recording, recording_failed, healthy)
    losses = []  # dicts per kill
    fill = {}
    http_failures = 0
    exited_early = None
    t0 = time.monotonic()
    next_scrape = next_sample = next_sweep = 0.0
    pending = None  # the current loss being followed
    filler = disk / "filler"

    def now():
        return time.monotonic() - t0

    try:
        while now() < a.duration:
            t = now()
            if node.poll() is not None:
                exited_early = (t, node.returncode)
                break
            if t >= next_scrape:
                next_scrape = t + 1.0
                m = metrics(a.port)
                h = healthz(a.port)
                if m is None or h is None:
                    if t > 10:
                        http_failures += 1
                else:
                    state = next((k.split('"')[1] for k, v in m.items() if k.startswith("omnirow_source_state{") and v == 1), "?")
                    scrapes.append((t, m.get("omnirow_frames_in_total", 0), state, m.get("omnirow_pipeline_alive", 0),
                                    m.get("omnirow_recording", 0), m.get("omnirow_recording_failed", 0), h.get("healthy")))
                    if pending is not None:
                        frames_in = m.get("omnirow_frames_in_total", 0)
                        if "lost_at" not in pending and state == "camera_lost":
                            pending["lost_at"] = t
                        if "restart_at" in pending and state == "streaming" and frames_in > pending["frames_at_restart"]:
                            pending["back_at"] = t
                            pending["frames_back"] = frames_in
                            losses.append(pending)
                            pending = None
            if t >= next_sample:
                next_sample = t + 10.0
                s = proc_sample(node.pid)
                if s:
                    # With the state the node was in: a camera being reconnected holds other
                    # sockets and threads than one streaming, so only like is compared with like.
                    last = scrapes[-1] if scrapes else None
                    steady = last is not None and t - last[0] < 2.0 and last[2] == "streaming" and last[4] == 1
                    samples.append((t,) + s + (steady,))
            if t >= next_sweep and fill.get("phase") != "full":
                next_sweep = t + 5.0
                files.sweep()
            if kills and t >= kills[0] and pending is None:
                kills.pop(0)
                last = scrapes[-1] if scrapes else (t, 0)
                sim.kill()
                sim.wait()
                # The rate the camera delivered before the kill (the simulator on a loaded
                # machine gives less than it is asked for): what "lost" is measured against.
                before = [x for x in scrapes if t - 20.0 <= x[0] <= t]
                rate = ((before[-1][1] - before[0][1]) / (before[-1][0] - before[0][0])
                        if len(before) >= 2 and before[-1][0] > before[0][0] else a.fps)
                pending = {"kill_at": t, "frames_at_kill": last[1], "rate_before": rate}
                time.sleep(a.down)
                sim = start_sim(a.loss)
                pending["restart_at"] = now()
                pending["frames_at_restart"] = (scrapes[-1][1] if scrapes else 0)
            if pending is not None and now() - pending["kill_at"] > 60:
                pending["back_at"] = None
                losses.append(pending)
                pending = None
            if fill_at is not None and t >= fill_at and not fill:
                st = os.statvfs(disk)
                free = st.f_bavail * st.f_frsize
                size = max(free - 48 * 2**20, 0)  # below the 96 MB reserve
                subprocess.run(["fallocate", "-l", str(size), str(filler)], check=True)
                fill = {"phase": "full", "filled_at": t}
            if fill.get("phase") == "full":
                if "stopped_at" not in fill and scrapes and scrapes[-1][5] == 1:
                    fill["stopped_at"] = t
                if t - fill["filled_at"] > 15 and "stopped_at" in fill:
                    filler.unlink()
                    fill["phase"] = "freed"
                    fill["freed_at"] = t
            if fill.get("phase") == "freed" and "resumed_at" not in fill and scrapes and scrapes[-1][4] == 1 and scrapes[-1][0] > fill["freed_at"]:
                fill["resumed_at"] = t
            time.sleep(0.05)
    finally:
        if node.poll() is None:
            node.send_signal(signal.SIGTERM)
            try:
                node.wait(timeout=20)
            except subprocess.TimeoutExpired:
                node.kill()
                node.wait()
        sim.kill()
        sim.wait()
        log.close()
    code = node.returncode
    files.sweep(keep_newest=False)
    remaining = sorted(rec_dir.glob("*.mcap"))
    replayed = None
    if remaining:
        r = subprocess.run(
            [a.bin, "run", "--replay", str(remaining[-1]), "--rate", "max", "--frames", "20", "--no-print", "--http", "off"],
            capture_output=True, text=True, env=env,
        )
        replayed = r.returncode == 0
    if tmpfs:
        for f in remaining:
            f.unlink()
        subprocess.run(["umount", str(disk)], check=False)

    # The judgement.
    after = [s for s in samples if s[0] >= warmup]
    steady = [s for s in after if s[4]]

    def spread(i, among):
        v = [s[i] for s in among]
        return (min(v), max(v)) if v else (0, 0)
    rss, fds, threads = spread(1, after), spread(2, after), spread(3, after)
    # Flatness is judged while streaming and recording (the steady state), where a leak would
    # show; the spread over every state is reported beside it.
    rss_steady, fds_steady = spread(1, steady), spread(2, steady)
    judged = len(steady) >= 6  # a minute of steady samples after warm-up, else too short to tell

    def slope_per_min(i):
        # Least-squares trend of the steady samples, per minute: a leak is a positive slope.
        if len(steady) < 2:
            return 0.0
        ts = [s[0] / 60 for s in steady]
        vs = [s[i] for s in steady]
        mt, mv = sum(ts) / len(ts), sum(vs) / len(vs)
        den = sum((t - mt) ** 2 for t in ts)
        return sum((t - mt) * (v - mv) for t, v in zip(ts, vs)) / den if den else 0.0

    def flat(mm):
        return not judged or (mm[1] > 0 and (mm[1] - mm[0]) <= 0.1 * mm[1])

    recovered = [l for l in losses if l.get("back_at")]
    lost_frames = [max(0.0, l["rate_before"] * (l["back_at"] - l["kill_at"]) - (l["frames_back"] - l["frames_at_kill"])) for l in recovered]
    node_log = (out / "node.log").read_text()
    disk_msg = "the recording stopped" in node_log
    expected_code = 2 if fill else 0
    checks = {
        "node ran to the end": exited_early is None,
        f"exit code {expected_code} at SIGTERM": code == expected_code,
        f"{a.kills}/{a.kills} camera losses recovered": len(recovered) == a.kills,
        # Every pipeline thread looping (the node's own heartbeat), at every scrape.
        "no thread stopped (pipeline alive at every scrape)": len(scrapes) > 0 and all(s[3] == 1 for s in scrapes),
        "every recording intact": all(c[2] for c in files.checked) and len(files.checked) > 0,
        "the last recording replays": replayed is True,
        "HTTP answered every second": http_failures == 0,
        "RSS flat while streaming after warm-up (max-min <= 10%)" + ("" if judged else ": run too short to judge"): flat(rss_steady),
        "fds flat while streaming after warm-up (max-min <= 10%)" + ("" if judged else ": run too short to judge"): flat(fds_steady),
    }
    if tmpfs:
        checks["recording stopped at the reserve and resumed when freed"] = "stopped_at" in fill and "resumed_at" in fill
    summary = {
        "duration_s": a.duration,
        "fps": a.fps,
        "loss_per_thousand": a.loss,
        "kills": a.kills,
        "recoveries": len(recovered),
        "loss_detected_s": [round(l["lost_at"] - l["kill_at"], 2) for l in recovered if "lost_at" in l],
        "streaming_again_after_restart_s": [round(l["back_at"] - l["restart_at"], 2) for l in recovered],
        "frames_lost_per_loss": [round(x) for x in lost_frames],
        "fps_delivered_before_loss": [round(l["rate_before"], 2) for l in recovered],
        "camera_down_s": a.down,
        "rss_kb_min_max": rss,
        "fds_min_max": fds,
        "steady_samples": len(steady),
        "rss_kb_min_max_streaming": rss_steady,
        "fds_min_max_streaming": fds_steady,
        "rss_kb_trend_per_min": round(slope_per_min(1), 1),
        "timeline": [{"t_s": round(s[0], 1), "rss_kb": s[1], "fds": s[2], "threads": s[3], "streaming": s[4]} for s in samples],
        "threads_min_max": threads,
        "samples": len(samples),
        "scrapes": len(scrapes),
        "http_failures": http_failures,
        "recordings_checked": len(files.checked),
        "frames_recorded": sum(c[1] for c in files.checked),
        "bad_recordings": [c for c in files.checked if not c[2]],
        "disk_fill": fill or "skipped (needs root for the tmpfs)",
        "exit_code": code,
        "exited_early": exited_early,
        "load_average": open("/proc/loadavg").read().split()[:3],
        "checks": checks,
    }
    (out / "soak.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps({k: v for k, v in summary.items() if k not in ("checks", "timeline")}))
    for name, ok in checks.items():
        print(f"soak: {'ok  ' if ok else 'FAIL'} {name}")
    if not disk_msg and fill:
        print("soak: note: the node's log does not say the recording stopped")
    sys.exit(0 if all(checks.values()) else 1)


if __name__ == "__main__":
    main()
