"""A calibration in a robotics stack: a robot's own URDF, plain Pinocchio and inverse kinematics.

The UR5 URDF of the example-robot-data package (``ur_description/urdf/ur5_robot.urdf``, unedited,
ROS names: ``shoulder_pan_joint`` ... ``wrist_3_joint``, ``tool0``) is calibrated from the shared
UR5 laser-tracker grid (``../shared/real-data/jacobi2025-laser-tracker/UR5``, MIT licence, cited in
example 03) and used as a robotics stack uses it:

1. **Calibrate.** ``aacmm-pin import-points --format jacobi2025`` turns the grid and the 20 random
   test poses into campaigns; ``aacmm-pin discover --start dh --arm ur5_robot.urdf --sizes
   urdf/ur5.sizes.json`` adds to the DH model what it misses (encoder maps, backlash, compliance,
   crosstalk; ``--model proposed``: ``identify --model proposed``, DH errors and encoder maps, in
   half the time). The calibration folder holds ``calibrated.urdf`` (error frames),
   ``compact.urdf`` (the file's own link and joint names, the calibrated values folded into the
   joint origins, the tracker's point on ``tool0_point``) and ``compact.json`` (the rest: maps,
   extension terms, the frame to the tracker).
2. **A plain Pinocchio script.** ``pinocchio.buildModelFromUrdf`` loads ``compact.urdf`` with no
   aacmm_pin: the ROS names are there and its links are those of the file (plus the tool point),
   where ``calibrated.urdf`` has one per error frame. ``aacmm_pin.load_calibrated(folder)`` is the
   rest of the calibration at run time: Pinocchio's forward kinematics of ``compact.urdf`` at
   ``rt.true_angles(readouts)`` is ``rt.position(readouts)`` (to rounding: every term of the
   calibration is an angle error; a tilt or scale term would move the point off the URDF's, by
   its size).
3. **Inverse kinematics with pink.** The targets are the tracker's measured points of the 20 test
   poses, in the arm's frame (the calibration's frame to the tracker inverted). Pink
   (``FrameTask`` on the point's frame, position only) solves them one after the other, each from
   the last solution, on three models; where the arm really goes is the full calibration's point
   (``rt.position``) of the readouts commanded:

   * calibrated: pink on ``compact.urdf``, its true joint angles turned into the readouts to
     command by ``rt.readouts`` (the inverse encoder maps and extension terms);
   * no inverse maps: pink on ``compact.urdf``, its joint angles commanded as readouts;
   * uncalibrated: pink on the nominal ROS URDF (the tracker's point 31 mm along ``tool0``'s z, as
     the robot's own tool setting), its joint angles commanded as readouts.

   The rows are commanded in order, so the backlash terms see each axis' direction of motion from
   one target to the next. The reached errors are against the calibration, the best model of the
   arm there is; the calibration's own error on these poses (against the tracker) is printed
   above the table. Exits non-zero if the calibrated path's mean error is not below half the
   uncalibrated one's, or the inverse maps make it worse.

Needs ``pip install ".[test]"`` (pin-pink, its QP solver daqp, example-robot-data).

Run: ``python examples/06_robotics_stack.py [--data DIR] [--out DIR] [--model discovered|proposed]``
(about 10 s; ``--model proposed``: 4 s).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.metadata
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

import aacmm_pin as ap
from aacmm_pin.cli import main

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "real-data" / "jacobi2025-laser-tracker"
UR5_URDF = "robots/ur_description/urdf/ur5_robot.urdf"
"""The UR5 URDF's path inside the example-robot-data distribution's data folder."""
NOMINAL_TOOL = np.array([0.0, 0.0, 0.031])
"""The tracker's point on the nominal UR5, m in ``tool0``: the tool setting of the data set's
commanded positions."""
QP_SOLVER = "daqp"


def ur5_urdf() -> Path:
    """Return the path of example-robot-data's UR5 URDF, as the installed distribution lists it."""
    files = importlib.metadata.files("example-robot-data") or []
    for file in files:
        if str(file).endswith(UR5_URDF):
            return Path(str(file.locate()))
    raise SystemExit(f"example-robot-data lists no {UR5_URDF}: pip install example-robot-data")


def cli(log: Path, *args: str) -> None:
    """Run one ``aacmm-pin`` command; its output goes to ``log``; stop if it fails."""
    with log.open("a") as out, contextlib.redirect_stdout(out):
        print("$ aacmm-pin " + " ".join(args))
        status = main(list(args))
    if status:
        raise SystemExit(f"aacmm-pin {args[0]} failed (exit {status}); see {log}")


def calibrate(data: Path, out: Path, model: str) -> Path:
    """Import the UR5's grid and test poses, calibrate the ROS URDF on the grid; return the folder."""
    out.mkdir(parents=True, exist_ok=True)
    log = out / "commands.log"
    log.write_text("")
    for name, part in (("grid", "grid"), ("random", "random")):
        cli(log, "import-points", str(data / "UR5" / f"3D_UR5_uncalibrated_{part}_cleaned.csv"),
            "--format", "jacobi2025", "--out", str(out / name), "--force")
    arm = ["--arm", str(ur5_urdf()), "--sizes", str(ROOT / "urdf" / "ur5.sizes.json")]
    folder = out / "calibration"
    if model == "discovered":
        cli(log, "discover", str(out / "grid"), *arm, "--start", "dh", "--out", str(folder), "--force")
    else:
        cli(log, "identify", str(out / "grid"), *arm, "--model", "proposed", "--out", str(folder),
            "--force")
    print(f"calibrated {ur5_urdf().name} ({model} model) on the grid -> {folder} "
          f"(the commands' output: {log})")
    return folder


def link_names(model: pin.Model) -> list[str]:
    """Return the names of a Pinocchio model's links (its body frames)."""
    return [f.name for f in model.frames if f.type == pin.FrameType.BODY]


def plain_pinocchio(folder: Path, readouts: np.ndarray) -> ap.CalibratedArm:
    """Load compact.urdf in plain Pinocchio beside the runtime object; print what each holds."""
    compact = pin.buildModelFromUrdf(str(folder / "compact.urdf"))
    full = pin.buildModelFromUrdf(str(folder / "calibrated.urdf"))
    print(f"compact.urdf in plain Pinocchio: {len(link_names(compact))} links, joints "
          f"{', '.join(compact.names[1:])}; frames tool0 {compact.existFrame('tool0')}, "
          f"tool0_point {compact.existFrame('tool0_point')}")
    extra = len(link_names(full)) - len(link_names(compact))
    print(f"calibrated.urdf: {len(link_names(full))} links ({extra} more: its error frames), the "
          f"same joints {list(full.names[1:]) == list(compact.names[1:])}")

    rt = ap.load_calibrated(folder)  # compact.json: maps, extension terms, frame to the tracker
    data = compact.createData()
    point = compact.getFrameId(rt.tool_links[0])
    urdf_points = []
    for theta in rt.true_angles(readouts):  # the URDF's joint angles: maps and extension terms
        pin.framesForwardKinematics(compact, data, theta)
        urdf_points.append(data.oMf[point].translation.copy())
    gap = np.abs(np.array(urdf_points) - rt.position(readouts)).max()
    terms = ", ".join(rt.parameters.extensions) or "none"
    why = ("no tilt or scale term" if gap < 1e-9 else
           "a tilt or scale term moves the point off the URDF's, by its size")
    print(f"Pinocchio's FK of compact.urdf at rt.true_angles(q) vs rt.position(q), {len(readouts)} "
          f"test poses: max {gap:.1e} m (extension terms: {terms}; {why})")
    return rt


def solve_path(model: pin.Model, frame: str, targets: np.ndarray, q0: np.ndarray,
               tol: float = 1e-10, max_steps: int = 300) -> np.ndarray:
    """Reach every target's point in turn with pink, each from the last solution.

    Args:
        model: the arm's Pinocchio model.
        frame: the frame whose origin goes to the targets.
        targets: points in the model's root frame, shape (N, 3), m.
        q0: the configuration to start from, rad.
        tol: stop a target's iterations when the frame's origin is this close, m.
        max_steps: at most this many steps a target.

    Returns:
        The model's configuration at each target, shape (N, nq), rad.
    """
    import pink
    from pink.tasks import FrameTask

    configuration = pink.Configuration(model, model.createData(), q0)
    task = FrameTask(frame, position_cost=1.0, orientation_cost=0.0, gain=0.5)
    dt, out = 0.1, []
    for target in targets:
        task.set_target(pin.SE3(np.eye(3), target))
        for _ in range(max_steps):
            reached = configuration.get_transform_frame_to_world(frame).translation
            if np.linalg.norm(reached - target) < tol:
                break
            velocity = pink.solve_ik(configuration, [task], dt, solver=QP_SOLVER)
            configuration.integrate_inplace(velocity, dt)
        out.append(configuration.q.copy())
    return np.array(out)


class Reached(NamedTuple):
    """Where one way of commanding the arm takes its point: errors against the targets, mm."""

    label: str
    """How the readouts were found."""
    mean_mm: float
    """Mean distance of the reached point from its target."""
    max_mm: float
    """Largest distance."""


def reach(rt: ap.CalibratedArm, folder: Path, targets: np.ndarray, start: np.ndarray) -> list[Reached]:
    """Command the targets three ways (see the docstring); return each way's reached errors."""
    compact = pin.buildModelFromUrdf(str(folder / "compact.urdf"))
    nominal = pin.buildModelFromUrdf(str(ur5_urdf()))
    tool0 = nominal.frames[nominal.getFrameId("tool0")]
    nominal.addFrame(pin.Frame("tracker_point", tool0.parentJoint, nominal.getFrameId("tool0"),
                               tool0.placement * pin.SE3(np.eye(3), NOMINAL_TOOL),
                               pin.FrameType.OP_FRAME))
    true_angles = solve_path(compact, rt.tool_links[0], targets, start)
    ways = [("calibrated: compact.urdf + rt.readouts", rt.readouts(true_angles)),
            ("compact.urdf, no inverse maps", true_angles),
            ("uncalibrated: nominal ROS URDF", solve_path(nominal, "tracker_point", targets, start))]
    rows = []
    for label, readouts in ways:
        error = np.linalg.norm(rt.position(readouts) - targets, axis=1) * 1e3
        rows.append(Reached(label, float(error.mean()), float(error.max())))
    return rows


def run(data: Path, out: Path, model: str) -> list[Reached]:
    """Calibrate, load in plain Pinocchio, command the test poses' points; return the reached rows."""
    folder = calibrate(data, out, model)
    test = ap.read_campaign(out / "random").points
    assert test is not None
    rt = plain_pinocchio(folder, test.q)
    own = np.linalg.norm(rt.position(test.q, frame="mt") - test.point, axis=1).mean() * 1e3
    print(f"the calibration on the {len(test.q)} test poses (vs the tracker): mean {own:.4f} mm")
    return reach(rt, folder, rt.to_arm_frame(test.point), start=test.q[0])  # tracker -> arm


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the jacobi2025 data folder")
    parser.add_argument("--out", type=Path, default=ROOT / "examples" / "out" / "robotics-stack",
                        help="folder for the campaigns and the calibration "
                        "(default: examples/out/robotics-stack)")
    parser.add_argument("--model", choices=("discovered", "proposed"), default="discovered",
                        help="discover from DH (default), or identify DH errors + encoder maps")
    args = parser.parse_args()
    rows = run(args.data, args.out, args.model)
    print(f"\n{'reached error of pink solutions (mm)':<40} {'mean':>10}  {'max':>10}")
    for row in rows:
        print(f"{row.label:<40} {row.mean_mm:10.3g}  {row.max_mm:10.3g}")
    calibrated, no_inverse, uncalibrated = rows
    if not calibrated.mean_mm < 0.5 * uncalibrated.mean_mm:
        raise SystemExit("FAILED: the calibrated path is not clearly better than the uncalibrated one")
    if calibrated.mean_mm > no_inverse.mean_mm:
        raise SystemExit("FAILED: the inverse maps made the calibrated path worse")
