"""Cost per sample of stylus positions and full Jacobians: batched (aacmm_pin) against the strongest
baseline, an independent numpy transcription of the paper's Eq. (1)-(4) vectorised over the samples
with an analytic Jacobian (``benchmarks/handwritten_identify.py``), against Pinocchio called sample
by sample in a Python loop (the former implementation), and against a plain numpy loop of Eq. (2)
(a weak baseline: one sample at a time in Python).

Run: ``python benchmarks/kinematics.py`` (writes its section of BENCHMARKS.md).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import Parameters, load_arm, stylus_jacobians, stylus_positions  # noqa: E402
from aacmm_pin._blas import single_threaded_blas  # noqa: E402
from aacmm_pin.model.kinematics import identification_configuration  # noqa: E402
from benchmarks import handwritten_identify as hand  # noqa: E402
from benchmarks._report import machine, ratio, write_section  # noqa: E402
from tests.helpers import paper_stylus  # noqa: E402

REPEAT = 15
"""Rounds, each a fresh process that measures every method once; ratios' ranges are over the
rounds."""
N = 20_000
"""Random readouts of the default arm that each batched method evaluates."""
PLAIN = 500
"""Samples of the plain per-sample numpy loop in each round (about 50 ms)."""


def cpu(f, repeat: int = REPEAT) -> np.ndarray:
    """Return the CPU times of ``repeat`` calls, s (CPU: the 2 cores are often shared)."""
    times = []
    for _ in range(repeat):
        tic = time.process_time()
        f()
        times.append(time.process_time() - tic)
    return np.array(times)


def us(t: np.ndarray) -> str:
    """Median (min - max) of per-sample times t (s), in us."""
    return f"{np.median(t) * 1e6:.2f} ({t.min() * 1e6:.2f} - {t.max() * 1e6:.2f})"


def hand_positions(q: np.ndarray, params: Parameters) -> np.ndarray:
    """The hand-written numpy chain (vectorised over samples), r-CS positions, shape (N, 3), m."""
    maps = np.zeros((7, hand.N_NODES))
    return hand.stylus(q, dict(params.dh), np.asarray(params.tool), maps)[0]


def hand_jacobians(q: np.ndarray, params: Parameters) -> tuple[np.ndarray, np.ndarray]:
    """The hand-written numpy chain and its analytic Jacobian (vectorised over samples), in the
    MT-CS: positions (N, 3) m and the 38 columns (N, 3, 38) in aacmm_pin's order (X0, translation,
    7 axes, 22 DH, tool)."""
    maps = np.zeros((7, hand.N_NODES))
    abc, t = np.asarray(params.rotation_abc), np.asarray(params.translation)
    p, cols = hand.stylus(q, dict(params.dh), np.asarray(params.tool), maps, jacobian=True)
    r = (hand.rot(1, abc[1]) @ hand.rot(0, abc[0]) @ hand.rot(2, abc[2]))[0, :3, :3]
    jac = np.empty((len(q), 3, 38))
    jac[:, :, :3] = hand.to_mt_jacobian(p, abc)
    jac[:, :, 3:6] = np.eye(3)
    names = [f"A{k}" for k in range(1, 8)] + list(params.dh)
    jac[:, :, 6:35] = r @ np.stack([cols[k] for k in names], axis=2)
    jac[:, :, 35:] = r @ cols["tool"]
    return hand.to_mt(p, abc, t), jac


def loop_positions(model: pin.Model, q: np.ndarray, fid: int) -> np.ndarray:
    """Pinocchio forward kinematics, one sample at a time (the former implementation)."""
    data, out = model.createData(), np.empty((len(q), 3))
    forward, update = pin.forwardKinematics, pin.updateFramePlacement
    for i, qi in enumerate(q):
        forward(model, data, qi)
        out[i] = update(model, data, fid).translation
    return out


def loop_jacobians(model: pin.Model, q: np.ndarray, fid: int) -> tuple[np.ndarray, np.ndarray]:
    """Pinocchio frame Jacobian (LOCAL_WORLD_ALIGNED), one sample at a time."""
    data = model.createData()
    pos, jac = np.empty((len(q), 3)), np.empty((len(q), 6, model.nv))
    frame_jacobian, placements = pin.computeFrameJacobian, data.oMf
    for i, qi in enumerate(q):
        jac[i] = frame_jacobian(model, data, qi, fid, pin.LOCAL_WORLD_ALIGNED)
        pos[i] = placements[fid].translation
    return pos, jac


def _setup():
    """The default arm, nominal parameters, the readouts and what the Pinocchio loop needs."""
    arm = load_arm()
    params = Parameters.nominal(arm)
    q = np.random.default_rng(0).uniform(-3, 3, (N, 7))
    qi = identification_configuration(arm, params, q, "mt")
    return arm, params, q, qi, arm.identification, arm.identification.stylus_frame


def one_round() -> dict[str, float]:
    """Time every method once in this process (after one untimed call of each), CPU s per sample."""
    arm, params, q, qi, ident, fid = _setup()
    methods = {
        "pos": (lambda: stylus_positions(arm, params, q), N),
        "jac": (lambda: stylus_jacobians(arm, params, q, frame="mt"), N),
        "hand_pos": (lambda: hand_positions(q, params), N),
        "hand_jac": (lambda: hand_jacobians(q, params), N),
        "loop_pos": (lambda: loop_positions(ident.model, qi, fid), N),
        "loop_jac": (lambda: loop_jacobians(ident.model, qi, fid), N),
        "plain": (lambda: [paper_stylus(qk, params.dh, params.tool) for qk in q[:PLAIN]], PLAIN),
    }
    with single_threaded_blas():
        for f, _ in methods.values():  # warm-up: lazy caches, first allocations
            f()
        return {k: float(cpu(f, 1)[0] / count) for k, (f, count) in methods.items()}


def main() -> None:
    # each round a fresh process: the spread then holds what differs between processes (memory
    # layout, caches) as well as within one, so that a rerun falls within it
    rounds = [json.loads(subprocess.run([sys.executable, __file__, "--round"], check=True,
                                        capture_output=True, text=True).stdout.splitlines()[-1])
              for _ in range(REPEAT)]
    runs = {k: [r[k] for r in rounds] for k in rounds[0]}
    arm, params, q, qi, ident, fid = _setup()
    n = N
    t = {k: np.array(v) for k, v in runs.items()}
    ours = stylus_jacobians(arm, params, q, frame="mt")
    same = np.abs(ours.position - loop_jacobians(ident.model, qi, fid)[0])
    hand_p, hand_j = hand_jacobians(q, params)
    mine = np.concatenate([ours.rotation, ours.translation, ours.angles, ours.dh, ours.tool], axis=2)
    same_hand = max(np.abs(stylus_positions(arm, params, q) - hand_positions(q, params)).max(),
                    np.abs(ours.position - hand_p).max())
    same_hand_jac = np.abs(mine - hand_j).max()

    def row(what: str, fast: str, ref: str) -> str:
        return (f"| {what} | {us(t[fast])} | {us(t[ref])} | {ratio(t[ref], t[fast], '.1f', name=what)} |")

    body = f"""## Kinematics cost per sample (`python benchmarks/kinematics.py`)

{machine()}; {n} random readouts of the default arm, CPU time, one BLAS thread;
median (range) of {REPEAT} rounds, each a fresh process that times every method once after an
untimed call of each (the plain numpy loop on {PLAIN} samples), ratios of the medians (range: the
ratio within each round, over the rounds of this run and of the earlier runs named below).
`stylus_positions` / `stylus_jacobians` evaluate all samples at once (`aacmm_pin.model._chain`: the
joint placements and axes are read from Pinocchio's identification model once, the products along
the chain and the Jacobian columns are vectorised over samples). The batched times include building
the configurations and splitting the Jacobian into its blocks.

Baselines, strongest first:
- hand-written numpy, vectorised over the samples (`benchmarks/handwritten_identify.py`'s chain, an
  independent transcription of Eq. (1)-(4) that imports neither aacmm_pin nor Pinocchio; analytic
  Jacobian: rotation steps a x (p - o), translation steps a; the same 38 columns in the MT-CS,
  written into one preallocated array); it agrees with aacmm_pin to {same_hand:.1e} m in position
  and {same_hand_jac:.1e} in the Jacobian's entries (m or m/rad) at these readouts;
- Pinocchio called once per sample in a Python loop (`forwardKinematics` + `updateFramePlacement`,
  `computeFrameJacobian`), as these functions did before; its configurations built beforehand
  (not timed); it agrees to {same.max():.1e} m;
- weak: a plain numpy transcription of Eq. (2), position only (`tests/helpers.py`), one sample
  at a time in Python.

| what | aacmm_pin batched (us per sample) | baseline (us per sample) | baseline / aacmm_pin |
|---|---|---|---|
{row("stylus position vs hand-written numpy, vectorised", "pos", "hand_pos")}
{row("stylus position vs Pinocchio per-sample loop", "pos", "loop_pos")}
{row("stylus position vs plain numpy Eq. (2) per-sample loop (weak)", "pos", "plain")}
{row("position + full Jacobian (38 columns: X0, translation, 7 axes, 22 DH, tool) vs "
     "hand-written numpy, vectorised", "jac", "hand_jac")}
{row("position + full Jacobian vs Pinocchio per-sample loop", "jac", "loop_jac")}

`tests/test_chain.py` checks positions and every Jacobian column against Pinocchio to 1e-12 on four
arms, a tree included. Map-node columns follow from the axis columns by the interpolation weights
(two per axis and sample) and add no kinematics cost."""
    write_section("kinematics", body)


if __name__ == "__main__":
    if sys.argv[1:] == ["--round"]:
        print(json.dumps(one_round()))
    else:
        main()
