"""Cost of the runtime object (``aacmm_pin.load_calibrated``) on one sample and on batches, against
Pinocchio's own forward kinematics of the same model, a careful hand-written wrapper (numpy's
``interp`` per mapped axis, then Pinocchio), and ``aacmm_pin.predict`` called per sample.

Run: ``python benchmarks/runtime.py`` (writes its section of BENCHMARKS.md).
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
import aacmm_pin as ap  # noqa: E402
from aacmm_pin import effects as fx  # noqa: E402
from aacmm_pin._blas import single_threaded_blas  # noqa: E402
from benchmarks._report import machine, ratio, write_section  # noqa: E402
from tests.helpers import SAMPLE  # noqa: E402

REPEAT = 9
"""Rounds, each a fresh process that times every method once."""
CALLS = 20_000
"""Single-sample calls per method and round (about 0.05 - 0.3 s each)."""
SLOW_CALLS = 200
"""Calls of the slow single-sample paths (predict per sample, extension terms)."""
BATCH = 10_000
"""Samples of the batch path."""


def arms() -> dict[str, tuple[ap.Arm, ap.Parameters]]:
    """The calibrations measured: the default AACMM with the sample campaign's truth (DH errors and
    maps on all seven axes), the UR5 with random DH errors and maps on its six axes, and the AACMM
    with a gravity compliance term besides (the extension path)."""
    aacmm = ap.load_arm()
    truth = ap.read_parameters(SAMPLE / "truth.json")
    ur5 = ap.load_arm("ur5")
    rng = np.random.default_rng(0)
    nominal = ap.Parameters.nominal(ur5)
    ur5_params = nominal.replace(
        dh={k: rng.normal(0.0, 1e-4) for k in nominal.dh},
        encoder_maps={a: ap.EncoderMap(rng.normal(0.0, 1e-4, 72)) for a in range(1, 7)})
    compliant = truth.replace(extensions={fx.compliance(2).key: np.array([1e-5])})
    return {"aacmm7": (aacmm, truth), "ur5": (ur5, ur5_params),
            "aacmm7 + compliance[A2]": (aacmm, compliant)}


def _readouts(arm: ap.Arm, n: int) -> np.ndarray:
    lim = arm.joint_limits
    return np.random.default_rng(1).uniform(lim[:, 0], lim[:, 1], (n, arm.n_axes))


def per_call(f, calls: int) -> float:
    """CPU seconds per call of ``f`` over ``calls`` calls (after 20 untimed ones)."""
    for _ in range(20):
        f()
    tic = time.process_time()
    for _ in range(calls):
        f()
    return (time.process_time() - tic) / calls


def hand_wrapper(arm: ap.Arm, params: ap.Parameters, model: pin.Model, data: pin.Data, fid: int):
    """A careful engineer's wrapper: each map as ``np.interp`` over its nodes (periodic), then
    Pinocchio's forward kinematics; no argument checks."""
    tables = {a - 1: (np.append(m.nodes, m.nodes[0] + 2 * np.pi), np.append(m.values, m.values[0]))
              for a, m in params.encoder_maps.items()}

    def position(q: np.ndarray) -> np.ndarray:
        theta = q.copy()
        for a, (nodes, values) in tables.items():
            theta[a] += np.interp(np.mod(q[a] + np.pi, 2 * np.pi) - np.pi, nodes, values)
        pin.forwardKinematics(model, data, theta)
        return pin.updateFramePlacement(model, data, fid).translation.copy()
    return position


def one_round() -> dict[str, float]:
    """Time every method once in this process, CPU s per call (batch: per sample)."""
    out = {}
    with single_threaded_blas():
        for name, (arm, params) in arms().items():
            rt = ap.CalibratedArm(arm, params)
            q = _readouts(arm, BATCH)
            q1 = q[0].copy()
            model, data, fid = rt.model, rt.model.createData(), rt.tool_frames[0]

            def fk() -> np.ndarray:
                pin.forwardKinematics(model, data, q1)
                return pin.updateFramePlacement(model, data, fid).translation

            slow = bool(params.extensions)
            calls = SLOW_CALLS if slow else CALLS
            hand = hand_wrapper(arm, params, model, data, fid)
            theta = rt.true_angles(q1)
            out |= {f"{name}|fk": per_call(fk, CALLS),
                    f"{name}|one": per_call(lambda: rt.position(q1), calls),
                    f"{name}|hand": per_call(lambda: hand(q1), CALLS),
                    f"{name}|predict_one": per_call(lambda: ap.predict(arm, params, q1[None]),
                                                    SLOW_CALLS),
                    f"{name}|jac_one": per_call(lambda: rt.jacobian(q1), calls),
                    f"{name}|pin_jac": per_call(lambda: pin.computeFrameJacobian(
                        model, data, theta, fid, pin.LOCAL_WORLD_ALIGNED), CALLS),
                    f"{name}|inverse_one": per_call(lambda: rt.readouts(theta), calls),
                    f"{name}|batch": per_call(lambda: rt.position(q), 3) / BATCH,
                    f"{name}|predict_batch": per_call(lambda: ap.predict(arm, params, q), 3) / BATCH}
    return out


def us(t: np.ndarray) -> str:
    """Median (min - max) of per-call times t (s), in us."""
    return f"{np.median(t) * 1e6:.2f} ({t.min() * 1e6:.2f} - {t.max() * 1e6:.2f})"


def main() -> None:
    rounds = [json.loads(subprocess.run([sys.executable, __file__, "--round"], check=True,
                                        capture_output=True, text=True).stdout.splitlines()[-1])
              for _ in range(REPEAT)]
    t = {k: np.array([r[k] for r in rounds]) for k in rounds[0]}
    same = {}
    for name, (arm, params) in arms().items():
        rt = ap.CalibratedArm(arm, params)
        q = _readouts(arm, 200)
        ref = ap.predict(arm, params, q)
        one = np.array([rt.position(qi) for qi in q]) if not params.extensions else None
        same[name] = max(np.abs(rt.position(q) - ref).max(),
                         0.0 if one is None else np.abs(one - ref).max())

    rows = []
    for name in arms():
        def row(what: str, ours: str, base: str, fmt: str = ".1f", key: str = name) -> str:
            return (f"| {key} | {what} | {us(t[f'{key}|{ours}'])} | {us(t[f'{key}|{base}'])} | "
                    f"{ratio(t[f'{key}|{ours}'], t[f'{key}|{base}'], fmt, name=f'{key}: {what}')} |")
        rows += [row("one sample: position / Pinocchio's forward kinematics", "one", "fk"),
                 row("one sample: position / hand-written np.interp + Pinocchio", "one", "hand",
                     ".2f"),
                 row("one sample: position / ap.predict of one sample", "one", "predict_one", ".4f"),
                 row("one sample: Jacobian (6 x n) / Pinocchio's frame Jacobian", "jac_one",
                     "pin_jac"),
                 row("one sample: readouts of true angles (inverse) / forward kinematics",
                     "inverse_one", "fk"),
                 row(f"batch of {BATCH}: position per sample / ap.predict's", "batch",
                     "predict_batch", ".2f")]
    body = f"""## Runtime object (`python benchmarks/runtime.py`)

{machine()}; CPU time per call (batch rows: per sample), one BLAS thread; median (range) of
{REPEAT} rounds, each a fresh process that times every method after 20 untimed calls
({CALLS} calls of each single-sample method, {SLOW_CALLS} of `ap.predict` per sample and of the
extension path); ratios of the medians (range: the ratio within each round, over the rounds of
this run and of the earlier runs named below).

`CalibratedArm.position` of one readout vector: its checks (axis count, finite, not degrees), the
encoder maps in plain floats and one Pinocchio forward kinematics of the calibrated model loaded
once. Baselines on the same model and readouts: Pinocchio's `forwardKinematics` +
`updateFramePlacement` alone (the readouts taken as joint angles: no maps, no checks), a careful
hand-written wrapper (`np.interp` per mapped axis, then the same two Pinocchio calls, no checks),
and `ap.predict` on one sample (which builds the model from its URDF on every call). The arms:
the default AACMM with the sample campaign's truth (DH errors, maps on 7 axes), the UR5 with DH
errors and maps on 6 axes, and the AACMM with a gravity compliance term (the extension terms are
evaluated through the effect library: the gravity torques, on every call). The runtime object
agrees with `ap.predict` to {max(same.values()):.1e} m on these arms (batches, and one sample at a
time without extension terms).

| arm | what | runtime object (us) | baseline (us) | runtime / baseline |
|---|---|---|---|---|
{chr(10).join(rows)}

Issue 36's bound: one sample at most 10x Pinocchio's forward kinematics of the same arm (first
row of each arm; the extension path is not held to it) and the batch path where `ap.predict`'s
is (last row)."""
    write_section("runtime", body)


if __name__ == "__main__":
    if sys.argv[1:] == ["--round"]:
        print(json.dumps(one_round()))
    else:
        main()
