"""Work a command cannot finish is refused in one line before it starts (issue 39).

A URDF chain deeper than Pinocchio's parser can recurse (it died by SIGSEGV), a map step that
gives more nodes than a fit can hold (8.5 min, 5.5 GB, then MemoryError), more Monte Carlo workers
than the machine has cores (a fork storm) and a column range of a million names (a million lines
on the screen): each is one line with its numbers, exit status 2.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

import aacmm_pin as ap
from aacmm_pin.analyses import uncertainty
from aacmm_pin.errors import ArmModelError
from aacmm_pin.model.urdf_tree import MAX_CHAIN_JOINTS, read_urdf
from tests.helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}


def _chain_urdf(path: Path, joints: int, kind: str = "revolute") -> Path:
    """Write a URDF of one chain of ``joints`` joints (then the fixed joint ``tool``)."""
    out = ['<?xml version="1.0"?>', '<robot name="long">', '<link name="base"/>']
    for i in range(1, joints + 1):
        parent = "base" if i == 1 else f"l{i - 1}"
        out.append(f'<link name="l{i}"/><joint name="j{i}" type="{kind}"><parent link="{parent}"/>'
                   f'<child link="l{i}"/><origin xyz="0 0 0.01"/><axis xyz="0 0 1"/>'
                   '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>')
    out.append(f'<link name="stylus"/><joint name="tool" type="fixed"><parent link="l{joints}"/>'
               '<child link="stylus"/><origin xyz="0 0 0.1"/></joint></robot>')
    path.write_text("\n".join(out))
    return path


def _limited(seconds: int) -> None:
    """A child's limits: CPU seconds and 3 GB of address space (main's runs grew to 5.5 GB)."""
    resource.setrlimit(resource.RLIMIT_CPU, (seconds, seconds))
    resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, 3 * 2**30))


def _error_lines(err: str) -> list[str]:
    return [line for line in err.strip().splitlines() if "still working" not in line]


def test_a_chain_of_5000_links_is_refused_in_one_line_not_a_segfault(tmp_path):
    """axes on a 5,000-link chain: one line naming the file and the chain's length, exit 2 (main:
    SIGSEGV, exit 139, no message)."""
    urdf = _chain_urdf(tmp_path / "long.urdf", 5000)
    proc = subprocess.run([sys.executable, "-m", "aacmm_pin", "axes", str(urdf)], env=ENV,
                          capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: _limited(100))
    lines = _error_lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, (proc.returncode, proc.stderr[-500:])
    assert str(urdf) in lines[0] and "5,001 joints" in lines[0]
    assert f"at most {MAX_CHAIN_JOINTS:,}" in lines[0]


def test_the_chain_limit_is_a_boundary(tmp_path):
    """A chain of exactly the limit is read; one joint more is refused naming its last link."""
    read_urdf(_chain_urdf(tmp_path / "at.urdf", MAX_CHAIN_JOINTS - 1, "fixed"))  # + tool
    with pytest.raises(ArmModelError, match=f"{MAX_CHAIN_JOINTS + 1:,} joints ends at link "
                                            "'stylus'"):
        read_urdf(_chain_urdf(tmp_path / "over.urdf", MAX_CHAIN_JOINTS, "fixed"))


def test_a_map_step_too_fine_is_refused_before_the_work(tmp_path, small_sim):
    """identify --step-deg 0.01: one line with the nodes, unknowns and memory, exit 2, within a
    minute and 3 GB (main: 8.5 min, 5.5 GB, MemoryError); nothing written."""
    campaign = tmp_path / "camp"
    ap.write_campaign(small_sim.campaign, campaign)
    proc = subprocess.run([sys.executable, "-m", "aacmm_pin", "identify", str(campaign),
                           "--step-deg", "0.01", "--out", str(tmp_path / "cal")], env=ENV,
                          capture_output=True, text=True, timeout=300,
                          preexec_fn=lambda: _limited(60))
    lines = _error_lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, (proc.returncode, proc.stderr[-500:])
    assert "--step-deg" in lines[0] and "36,000 nodes a map, at most 720" in lines[0]
    assert "252,000 unknowns" in lines[0]
    assert not (tmp_path / "cal").exists()


def test_the_api_refuses_a_map_step_too_fine(small_sim, arm):
    """ap.identify(step_deg=0.01) raises ap.ArgumentError naming step_deg."""
    with pytest.raises(ap.ArgumentError, match="step_deg: 0.01 deg gives 36,000 nodes"):
        ap.identify(small_sim.campaign, arm, step_deg=0.01)


def _no_pool(*args: object, **kwargs: object) -> None:
    raise AssertionError("a process pool was started")


def test_more_workers_than_cores_are_refused_before_any_fork(tmp_path, small_sim, monkeypatch):
    """uncertainty --workers 1000: one line naming the cores, exit 2, no pool started, no output
    (main forked 1000 processes)."""
    monkeypatch.setattr(uncertainty, "ProcessPoolExecutor", _no_pool)
    campaign = tmp_path / "camp"
    ap.write_campaign(small_sim.campaign, campaign)
    status, err = run_cli(["uncertainty", str(campaign), "--workers", "1000", "--trials", "4",
                           "--out", str(tmp_path / "unc")])
    lines = _error_lines(err)
    assert status == 2 and len(lines) == 1, err
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert f"--workers: 1,000 processes on {cores} core" in lines[0]
    assert not (tmp_path / "unc").exists()


def test_the_api_refuses_more_workers_than_cores(small_sim, small_cal, monkeypatch):
    """monte_carlo(workers=1000) raises ap.ArgumentError before a pool starts."""
    monkeypatch.setattr(uncertainty, "ProcessPoolExecutor", _no_pool)
    with pytest.raises(ap.ArgumentError, match="workers: 1,000 processes on"):
        uncertainty.monte_carlo(small_cal, small_sim.campaign, 4, workers=1000)


def test_a_range_of_a_million_columns_is_one_line(tmp_path):
    """import-points --joints a1..a1000000: one line with the range's size, not a million."""
    source = tmp_path / "tracker.csv"
    source.write_text("a1,x,y,z\n1,2,3,4\n")
    status, err = run_cli(["import-points", str(source), "--joints", "a1..a1000000", "--point",
                           "x,y,z", "--out", str(tmp_path / "camp")])
    lines = _error_lines(err)
    assert status == 2 and len(lines) == 1, err[:2000]
    assert "a range of 1,000,000 columns" in lines[0] and "at most 256" in lines[0]
