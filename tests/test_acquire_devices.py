"""End-to-end tests of acquisition on real pseudo-terminals, with simulator-driven fake devices.

Two ``fake-devices`` processes (location 1: Heidenhain-style gauges; location 2: Mitutoyo-style)
inject garbage, checksum errors, out-of-range values and silences; ``acquire`` records both
locations into one campaign, which ``read_campaign`` and ``identify`` must accept. Every process
and thread started here ends by itself (``--seconds``) or is ended by its id.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from aacmm_pin.campaign import read_campaign
from aacmm_pin.cli.acquisition import add_parsers

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
CLI = [sys.executable, "-m", "aacmm_pin"]
FAULTS = ["--garbage", "0.01", "--checksum-errors", "0.01", "--out-of-range", "0.005",
          "--timeouts", "1", "--silence-s", "0.15"]
ACQUIRE = ["--timeout-s", "0.1", "--poll-hz", "500", "--decimate", "2", "--status-s", "0.2"]


def run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.handler(args)


@pytest.fixture(scope="module")
def fakes(tmp_path_factory):
    """Two fake-devices processes (locations 1 and 2) with faults; yields their JSON descriptions."""
    folder = tmp_path_factory.mktemp("fakes")
    procs, paths = [], []
    for location, fmt in ((1, "heidenhain"), (2, "mitutoyo")):
        path = folder / f"fake{location}.json"
        log = (folder / f"fake{location}.log").open("w")
        procs.append(subprocess.Popen(
            [*CLI, "fake-devices", "--location", str(location), "--gauge-format", fmt,
             "--effects", "dh,rtest", "--rate-hz", "500", "--seconds", "40", "--json", str(path),
             *FAULTS], stdout=log, stderr=subprocess.STDOUT, env=ENV, cwd=ROOT))
        paths.append(path)
    deadline = time.monotonic() + 30
    while not all(p.exists() for p in paths) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(p.exists() for p in paths), "fake-devices did not start"
    yield {k + 1: json.loads(p.read_text()) for k, p in enumerate(paths)}
    for proc in procs:
        proc.send_signal(signal.SIGTERM)
    for proc, location in zip(procs, (1, 2)):
        assert proc.wait(timeout=10) == 0
        injected = json.loads((folder / f"fake{location}.json").read_text())["injected"]
        assert all(v > 0 for v in injected.values()), injected


@pytest.fixture(scope="module")
def recorded(fakes, tmp_path_factory):
    """Both locations acquired into one campaign folder; yields (folder, summaries)."""
    folder = tmp_path_factory.mktemp("campaign")
    summaries = {}
    for location in (1, 2):
        status = run(["acquire", str(folder), *fakes[location]["acquire_args"], "--seconds", "2",
                      *ACQUIRE])
        assert status == 0
        summaries[location] = json.loads((folder / f"acquire-location{location}.json").read_text())
    return folder, summaries


def test_acquired_campaign_is_identified(recorded):
    """fake-devices + acquire on ptys give a campaign that read_campaign and identify accept."""
    from aacmm_pin.identification import identify

    folder, summaries = recorded
    campaign = read_campaign(folder)
    assert campaign.spat is not None and sorted(campaign.locations) == [1, 2]
    for location in (1, 2):
        n = int((campaign.spat.location == location).sum())
        assert n == summaries[location]["rows_written"] > 100
    assert (np.diff(campaign.spat.t) >= 0).all()
    cal = identify(campaign, model="dh")
    # dh + rtest effects only: the dh model fits to the R-Test noise (2 um per coordinate), plus the
    # few rows paired across a posture jump of the fake arm (within one gauge period).
    assert cal.fit_rms < 4e-6, cal.fit_rms


def test_faults_are_counted_and_absent_from_data(recorded, fakes):
    """Injected garbage, checksum errors, out-of-range values and silences are counted, never data."""
    folder, summaries = recorded
    campaign = read_campaign(folder)
    assert campaign.spat is not None
    for location in (1, 2):
        faults = summaries[location]["faults"]
        kinds = ["garbled", "checksum", "out_of_range", "timeout"]
        assert all(faults[k] > 0 for k in kinds), faults
        assert faults["port_lost"] == 0 and summaries[location]["status"] == 0
        sel = campaign.spat.location == location
        sent_q = np.array(fakes[location]["q_deg"])
        sent_d = np.array(fakes[location]["displacement_mm"])
        for q in np.degrees(campaign.spat.q[sel]):  # every row is a posture the arm sent
            assert np.abs(sent_q - q).max(axis=1).min() < 1e-7
        for axis, values in enumerate((campaign.spat.displacement[sel] * 1e3).T):
            # every coordinate is a reading a gauge sent (a channel may come from the posture
            # before a jump, so axes are checked one by one)
            assert np.abs(values[:, None] - sent_d[None, :, axis]).min(axis=1).max() < 1e-9


def test_killed_acquire_leaves_every_row(fakes, tmp_path):
    """SIGKILL mid-run leaves a valid campaign holding at least every row reported written."""
    proc = subprocess.Popen(
        [*CLI, "acquire", str(tmp_path), *fakes[1]["acquire_args"], *ACQUIRE],
        stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, env=ENV, cwd=ROOT, text=True)
    reported, deadline = 0, time.monotonic() + 20
    try:
        assert proc.stderr is not None
        for line in proc.stderr:  # status lines: "loc 1 | <rows> rows ..."
            if line.startswith("loc 1 |"):
                reported = int(line.split("|")[1].split()[0])
            if reported >= 100 or time.monotonic() > deadline:
                break
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    assert reported >= 100
    text = (tmp_path / "spat.csv").read_text()
    assert text.endswith("\n")
    campaign = read_campaign(tmp_path)
    assert campaign.spat is not None and len(campaign.spat.q) >= reported


def test_port_that_disappears_stops_the_run_cleanly(tmp_path):
    """A port gone for good ends the run with status 1, a report, and every good row on disk."""
    from aacmm_pin.acquire.fake_devices import FakeConfig, FakeDevices
    from aacmm_pin.acquire.nest import Nest
    from aacmm_pin.acquire.session import AcquisitionConfig, acquire

    nest = Nest(np.array([[1.0, 0, 0], [0.6, 0.8, 0], [0, 0.6, 0.8]]))  # a skewed nest
    devices = FakeDevices(FakeConfig(location=3, postures=20, rate=500, nest=nest,
                                     effects=("dh", "rtest"))).start()
    timer = threading.Timer(1.5, devices.stop)  # the devices vanish after 1.5 s
    timer.start()
    try:
        config = AcquisitionConfig(
            tmp_path, 3, devices.arm_path, tuple(devices.gauges), zero=devices.zero, nest=nest,
            seconds=10.0, give_up=0.4, timeout=0.1, poll_interval=1 / 500)
        tic = time.monotonic()
        summary = acquire(config)
        elapsed = time.monotonic() - tic
    finally:
        timer.cancel()
        devices.stop()
    assert summary.status == 1 and "gone" in summary.stop_reason
    assert elapsed < 4.0
    assert summary.ports["arm"].port_lost >= 1
    campaign = read_campaign(tmp_path)
    assert campaign.spat is not None and len(campaign.spat.q) == summary.rows_written > 100
    sent = devices.displacement_mm  # the skewed nest's readings give back the displacement
    d = campaign.spat.displacement * 1e3
    assert np.mean([np.abs(sent - row).max(axis=1).min() < 2e-9 for row in d]) > 0.95
    assert json.loads(config.summary_path.read_text())["status"] == 1
