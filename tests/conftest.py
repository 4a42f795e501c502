"""Shared, session-scoped fixtures: the default arm and the simulated campaigns several modules use.

Everything here is built once per session and shared by every test that asks for it, so tests must
not change these objects: the campaigns' arrays are read-only; copy anything else (``Parameters``
arrays, a calibration's ``x``) before changing it.

BLAS runs single-threaded in the test process and in what it starts (worker processes, the
examples): the work is many products of a few hundred columns, which gain nothing from BLAS threads,
while threads spinning on two busy cores slow them down many times (``aacmm_pin._blas``). Set
``OPENBLAS_NUM_THREADS`` (or ``OMP_NUM_THREADS``) to choose otherwise.

The CLI's heartbeat ("still working" after a silence, :class:`aacmm_pin.progress.Heartbeat`) is
silenced in-process: a command's output is then the same on a busy machine as on an idle one
(``tests/test_progress.py`` sets its own times).
"""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator

import pytest

if not {"OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"} & set(os.environ):
    os.environ["OPENBLAS_NUM_THREADS"] = "1"  # subprocesses and spawned workers
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1)  # this process, whose BLAS may be loaded already

import aacmm_pin as ap  # noqa: E402


@pytest.hookimpl(tryfirst=True)
def pytest_cmdline_main(config: pytest.Config) -> None:
    """``-s`` (show what tests print) runs in this process, as pytest-xdist does for ``--pdb``.

    pyproject's addopts run the tests on ``-n auto`` worker processes, whose prints ``-s`` cannot
    show; an explicit ``-n N`` (a number) is kept, ``-n auto`` with ``-s`` runs in one process.
    """
    if config.getoption("capture", None) == "no" and config.getoption("numprocesses", None) == "auto":
        config.option.numprocesses = 0


@pytest.fixture(autouse=True)
def _no_heartbeat(monkeypatch: pytest.MonkeyPatch) -> None:
    import aacmm_pin.progress as progress

    monkeypatch.setattr(progress, "FIRST_BEAT_S", float("inf"))
    monkeypatch.setattr(progress, "HEARTBEAT_S", float("inf"))


SMALL = {"samples_per_location": 50, "samples_per_socket": 5, "bar_placements": 2}
"""A small campaign (seed 0, default effects): 4 x 50 SPAT samples, a bar at 2 placements."""


@pytest.fixture(scope="session")
def arm() -> ap.Arm:
    """The embedded default arm (aacmm7)."""
    return ap.load_arm()


@pytest.fixture(scope="session")
def effects_sim(arm: ap.Arm) -> ap.Simulation:
    """A tiny campaign (4 x 15 SPAT samples, 1 bar placement) with compliance and temperatures."""
    config = ap.SimulationConfig(seed=3, effects=("dh", "encoder", "rtest", "compliance",
                                                  "thermal"), samples_per_location=15,
                                 bar_placements=1, samples_per_socket=5)
    return ap.simulate_campaign(arm, config)


@pytest.fixture(scope="session")
def small_sim(arm: ap.Arm) -> ap.Simulation:
    """The small campaign :data:`SMALL` (DH and encoder errors, the sphere moving in its seat)."""
    return ap.simulate_campaign(arm, ap.SimulationConfig(**SMALL))  # type: ignore[arg-type]


@pytest.fixture(scope="session")
def process_sim(arm: ap.Arm) -> ap.Simulation:
    """A campaign a command works on for about a second (4 x 40 SPAT samples, 2 bar placements):
    long enough to be stopped mid-run by the kill and Ctrl-C tests."""
    return ap.simulate_campaign(arm, ap.SimulationConfig(
        seed=0, samples_per_location=40, samples_per_socket=5, bar_placements=2))


@pytest.fixture(scope="session")
def small_cal(arm: ap.Arm, small_sim: ap.Simulation) -> ap.Calibration:
    """The proposed model identified on the small campaign."""
    return ap.identify(small_sim.campaign, arm, model="proposed")


@pytest.fixture(scope="session")
def paper_sim(arm: ap.Arm) -> ap.Simulation:
    """Seed 0's paper-sized campaign (default configuration: DH and encoder errors)."""
    return ap.simulate_campaign(arm, ap.SimulationConfig(seed=0))


@pytest.fixture(scope="session")
def paper_cal(arm: ap.Arm, paper_sim: ap.Simulation) -> ap.Calibration:
    """The proposed model (R-Test displacements used) identified on :func:`paper_sim`."""
    return ap.identify(paper_sim.campaign, arm, model="proposed")


@pytest.fixture(scope="session")
def sim_400(arm: ap.Arm) -> ap.Simulation:
    """400 SPAT samples (seed 2, 4 x 100), DH and encoder errors."""
    return ap.simulate_campaign(arm, ap.SimulationConfig(seed=2, samples_per_location=100))


@pytest.fixture(scope="session")
def cal_400(arm: ap.Arm, sim_400: ap.Simulation) -> ap.Calibration:
    """The proposed model identified on :func:`sim_400`."""
    return ap.identify(sim_400.campaign, arm)


@pytest.fixture
def sigint_as_from_a_terminal() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt in this process and in the commands it starts, as when the
    tests run from a terminal: a shell's background job (and every process it starts) inherits
    SIGINT ignored, and a command keeps that ignore."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)
