"""Acquisition rate and CPU use with the arm and the gauges at 1 kHz each, on pseudo-terminals.

Run: ``python benchmarks/acquire.py [SECONDS]`` (default 10 s per configuration, about 30 s in
all). Writes its section of BENCHMARKS.md.

``fake-devices`` runs in its own process (arm at 1 kHz; Heidenhain-style gauges answering
``acquire``'s requests at 1 kHz each, or one Mitutoyo-style port streaming three channels at 1 kHz);
``acquire`` runs in this process, so its CPU time (every reader thread and the pairing/writing
loop) is this process's CPU time over the run. The devices' CPU time is read from /proc.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from aacmm_pin.acquire.protocols import parse_gauge_spec  # noqa: E402
from aacmm_pin.acquire.session import AcquisitionConfig, acquire  # noqa: E402
from aacmm_pin.data.campaign import read_campaign  # noqa: E402
from benchmarks._report import machine, write_section  # noqa: E402

RATE = 1000.0


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system) of a process so far, s (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def other_posture(campaign: Path, fake: dict) -> int:
    """Return how many rows carry a reading of another posture than their readouts."""
    spat = read_campaign(campaign).spat
    assert spat is not None
    q = np.degrees(spat.q)
    posture = np.abs(np.array(fake["q_deg"])[None] - q[:, None]).max(axis=2).argmin(axis=1)
    wrong = np.abs(spat.displacement * 1e3 - np.array(fake["displacement_mm"])[posture]) > 2e-9
    return int(wrong.any(axis=1).sum())


def bench(gauge_format: str, seconds: float, work: Path) -> dict:
    """Run fake-devices + acquire for ``seconds``; return rates and CPU use."""
    desc = work / f"fake-{gauge_format}.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "aacmm_pin", "fake-devices", "--gauge-format",
         gauge_format, "--rate-hz", str(RATE), "--seconds", str(seconds + 30), "--json",
         str(desc)], stdout=subprocess.DEVNULL, env=env, cwd=ROOT)
    try:
        while not desc.exists():
            time.sleep(0.05)
        fake = json.loads(desc.read_text())
        campaign = work / f"campaign-{gauge_format}"
        config = AcquisitionConfig(
            campaign, 1, fake["arm"], tuple(parse_gauge_spec(g) for g in fake["gauges"]),
            zero=np.array(fake["zero_mm"]) * 1e-3, seconds=seconds, poll_interval=1.0 / RATE,
            status_interval=1.0)
        time.sleep(0.5)
        cpu0, fake0, wall0 = time.process_time(), cpu_seconds(proc.pid), time.perf_counter()
        summary = acquire(config, stop=threading.Event())
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        fake_cpu = cpu_seconds(proc.pid) - fake0
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    ports = summary.ports
    mixed = other_posture(campaign, fake)
    gauge_lines = sum(c.lines for name, c in ports.items() if name != "arm")
    return {"format": gauge_format, "arm_hz": ports["arm"].lines / summary.duration_s,
            "gauge_hz": gauge_lines / 3 / summary.duration_s, "rows_hz": summary.rate_hz,
            "unpaired": summary.unpaired / max(ports["arm"].lines, 1),
            "moving": summary.moving / max(ports["arm"].lines, 1), "mixed": mixed,
            "faults": sum(summary.faults.values()),
            "kinds": ", ".join(f"{k} {v}" for k, v in summary.faults.items() if v),
            "cpu": cpu / wall, "fake_cpu": fake_cpu / wall,
            "us_per_row": cpu / max(summary.rows_written, 1) * 1e6}


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    with tempfile.TemporaryDirectory() as tmp:
        results = [bench(fmt, seconds, Path(tmp)) for fmt in ("heidenhain", "mitutoyo")]
    rows = "\n".join(
        f"| {r['format']} | {r['arm_hz']:.0f} | {r['gauge_hz']:.0f} | {r['rows_hz']:.0f} | "
        f"{r['unpaired'] * 100:.1f} | {r['moving'] * 100:.1f} | {r['mixed']} | "
        f"{r['faults']} | {r['cpu'] * 100:.0f} | {r['us_per_row']:.0f} | "
        f"{r['fake_cpu'] * 100:.0f} |" for r in results)
    kinds = "; ".join(f"{r['format']}: {r['kinds']}" for r in results if r["kinds"]) or "none"
    write_section("acquire", f"""## Acquisition rate and CPU use (`python benchmarks/acquire.py`)

{machine()}; {seconds:g} s per run. The arm streams `$A,...*HH` lines at 1 kHz on a pty; the gauges
are three Heidenhain-style counters polled at 1 kHz each (one pty each) or one Mitutoyo-style port
streaming its three channels at 1 kHz. `acquire` pairs, converts and appends one flushed row of
spat.csv per arm sample. CPU is in % of one core over the run. A rate and a cost with no
baseline: there is no other acquisition implementation to compare with; the devices' 1 kHz is the
target. One run per configuration (the rate is set by the devices; the CPU use varies with the
machine's load).

| gauges | arm lines/s | gauge lines/s per channel | rows/s written | unpaired (%) | \
at a change (%) | rows of another posture | faults | acquire CPU (%) | acquire CPU per row (us) | \
fake devices CPU (%) |
|---|---|---|---|---|---|---|---|---|---|---|
{rows}

No fault was injected (faults counted by kind: {kinds}); `unpaired` are arm samples without a
reading of every gauge channel within 10 ms (not written). The fake arm jumps between postures
(simulated SPAT postures held 50 ms each): `at a change` are arm samples whose readouts or
readings changed within the pair's time window (dropped), `rows of another posture` the rows
written whose readings belong to another posture than their readouts (checked against what the
devices sent). CPU per row counts every reader thread and the pairing/writing loop.""")


if __name__ == "__main__":
    main()
