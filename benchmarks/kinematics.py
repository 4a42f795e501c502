"""Cost per sample of stylus positions and full Jacobians: batched (aacmm_pin) against Pinocchio
called sample by sample in a Python loop, and against a plain numpy loop of the paper's Eq. (2).

Run: ``python benchmarks/kinematics.py`` (writes its section of BENCHMARKS.md).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from aacmm_pin import Parameters, load_arm, stylus_jacobians, stylus_positions  # noqa: E402
from aacmm_pin._blas import single_threaded_blas  # noqa: E402
from aacmm_pin.model.kinematics import identification_configuration  # noqa: E402
from benchmarks._report import machine, write_section  # noqa: E402
from tests.helpers import paper_stylus  # noqa: E402

REPEAT = 5


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


def ratio(slow: np.ndarray, fast: np.ndarray) -> str:
    """The ratio of the medians and its range over the runs (paired in order: interleaved)."""
    r = slow / fast
    return f"{np.median(slow) / np.median(fast):.1f}x ({r.min():.1f} - {r.max():.1f})"


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


def main() -> None:
    arm = load_arm()
    ident = arm.identification
    params = Parameters.nominal(arm)
    n = 20_000
    q = np.random.default_rng(0).uniform(-3, 3, (n, 7))
    qi = identification_configuration(arm, params, q, "mt")
    fid = ident.stylus_frame
    with single_threaded_blas():
        runs = {k: [] for k in ("pos", "jac", "loop_pos", "loop_jac")}
        for _ in range(REPEAT):  # interleaved: each round measures every method once
            runs["pos"].append(cpu(lambda: stylus_positions(arm, params, q), 1)[0] / n)
            runs["jac"].append(cpu(lambda: stylus_jacobians(arm, params, q), 1)[0] / n)
            runs["loop_pos"].append(cpu(lambda: loop_positions(ident.model, qi, fid), 1)[0] / n)
            runs["loop_jac"].append(cpu(lambda: loop_jacobians(ident.model, qi, fid), 1)[0] / n)
        m = 2_000
        t_ref = cpu(lambda: [paper_stylus(qk, params.dh, params.tool) for qk in q[:m]], 3) / m
    t_pos, t_jac, t_loop_pos, t_loop_jac = (np.array(runs[k]) for k in
                                            ("pos", "jac", "loop_pos", "loop_jac"))
    same = np.abs(stylus_jacobians(arm, params, q).position - loop_jacobians(ident.model, qi, fid)[0])
    body = f"""## Kinematics cost per sample (`python benchmarks/kinematics.py`)

{machine()}; {n} random readouts of the default arm, CPU time, one BLAS thread; median (range) of
{REPEAT} interleaved runs (the plain numpy loop: 3 runs of {m} samples), ratios of the medians
(range: the ratio within each round).
`stylus_positions` / `stylus_jacobians` evaluate all samples at once (`aacmm_pin.model._chain`: the joint
placements and axes are read from Pinocchio's identification model once, the products along the
chain and the Jacobian columns are vectorised over samples); the loop calls Pinocchio once per
sample, as these functions did before.

| what | batched (us per sample) | Pinocchio per-sample loop (us) | batched vs loop | vs plain numpy Eq. (2) |
|---|---|---|---|---|
| stylus position | {us(t_pos)} | {us(t_loop_pos)} | {ratio(t_loop_pos, t_pos)} faster | \
{np.median(t_ref) / np.median(t_pos):.0f}x faster |
| position + full Jacobian (38 columns: X0, translation, 7 axes, 22 DH, tool) | \
{us(t_jac)} | {us(t_loop_jac)} | {ratio(t_loop_jac, t_jac)} faster | \
{np.median(t_ref) / np.median(t_jac):.0f}x faster |
| plain numpy transcription of Eq. (2), position only (`tests/helpers.py`), per-sample loop | \
{us(t_ref)} | | | 1x |

The batched and the looped positions agree to {same.max():.1e} m (`tests/test_chain.py` checks
positions and every Jacobian column against Pinocchio to 1e-12 on four arms, a tree included).
The batched times include building the configurations and splitting the Jacobian into its blocks.
Map-node columns follow from the axis columns by the interpolation weights (two per axis and
sample) and add no kinematics cost."""
    write_section("kinematics", body)


if __name__ == "__main__":
    main()
