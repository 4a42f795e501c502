"""Virtual arm and campaign simulator with switchable effects and a saved truth.

The virtual arm is the arm's URDF with random DH errors, tool error, encoder error maps (a few
harmonics per axis, stored as node tables so that linear interpolation reproduces them exactly) and
optional further effects that the paper's model lacks:

* ``dh``: DH errors (~0.1 mm, ~0.02 deg) and tool vector error;
* ``encoder``: angular position measurement errors, a few harmonics of a few to 20 arcsec per axis;
* ``rtest``: the sphere moving in its seat during the SPAT (up to ``rtest_max`` m, measured by
  the R-Test);
* ``compliance``: gravity-induced joint deflection, k_n x gravity torque of axis n (torques from the
  URDF inertias by Pinocchio's generalized gravity);
* ``thermal``: uniform thermal expansion of every length with the ``temp_c`` column;
* ``backlash``: a direction-dependent angular error of an axis (direction of the motion since the
  previous sample);
* ``lateral_compliance``: gravity-induced tilt of a joint about the two axes perpendicular to its
  own, (kx, ky) x the gravity moment about each (:mod:`aacmm_pin.effects.builtin.lateral_compliance`),
  held as extension terms of the truth (``truth.json`` ``extensions``) and applied by the model's
  own kinematics;
* ``crosstalk``: an axis' angle error that depends on a neighbour's angle, c cos + s sin of it
  (:mod:`aacmm_pin.effects.builtin.crosstalk`), held as extension terms of the truth too.

A campaign is SPATs and a length bar (:func:`simulate_campaign`), or, with ``points`` > 0, tool
points of every tool (alternately) measured by one instrument (a laser tracker, motion capture) in
its own frame (:func:`simulate_points`; trees such as a torso with two arms too).

Postures are found by damped Newton IK on the *true* model within the joint limits. Same seed, same
files. The truth is returned apart and never read by identification.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from aacmm_pin.data.campaign import Campaign, LengthBarLog, PointLog, SpatLog
from aacmm_pin.effects.calibrated import stylus_positions
from aacmm_pin.effects.forward import adjustment
from aacmm_pin.model import kinematics
from aacmm_pin.model.arm import Arm
from aacmm_pin.model.encoder_map import EncoderMap, node_angles
from aacmm_pin.model.kinematics import Adjustment, JointKinematics, ToolIndex, solve_ik
from aacmm_pin.model.parameters import Parameters
from aacmm_pin.model.samples import Samples, gravity_torques, motion_direction
from aacmm_pin.units import (
    ARCSEC,
    DEFAULT_SIMULATOR_EFFECTS,
    REFERENCE_TEMPERATURE_C,
    SIGMA_LOCATION,
    SIGMA_POINT,
    SIGMA_RTEST,
    SIMULATOR_EFFECTS,
    STEP_DEG,
)

EFFECTS = SIMULATOR_EFFECTS
DEFAULT_EFFECTS = DEFAULT_SIMULATOR_EFFECTS
BAR_LENGTHS = {("A", "B"): 0.361775, ("A", "C"): 0.711211}
"""The paper's bar: calibrated socket distances A-B and A-C, in m."""


@dataclass(frozen=True)
class SimulationConfig:
    """What to simulate. Lengths in m, angles in rad."""

    seed: int = 0
    """Seed of every random draw: same seed, same campaign."""
    effects: tuple[str, ...] = DEFAULT_EFFECTS
    """Effects switched on, from :data:`EFFECTS`."""
    samples_per_location: int = 200
    """SPAT samples per R-Test location."""
    location_xy: tuple[tuple[float, float], ...] = (
        (-0.13, -0.13), (0.13, -0.13), (0.13, 0.13), (-0.13, 0.13))
    """R-Test nest positions in the MT-CS (corners of a 260 mm square), m."""
    mt_translation: tuple[float, float, float] = (-0.58, 0.0, 0.0)
    """r-CS origin in the MT-CS, m (puts the nests 0.45-0.72 m from A1)."""
    rotation_sigma: float = np.radians(0.3)
    """Std of each of alpha0, beta0, gamma0 (a few tenths of a degree)."""
    samples_per_socket: int = 40
    """Length-bar postures per socket."""
    sigma_socket: float = 0.0
    """Scatter of the stylus centre seated in a bar socket, per coordinate (0: exact)."""
    bar_placements: int = 7
    """Length-bar placements around the arm."""
    dh_sigma_length: float = 1e-4
    """Std of the DH length errors and of the tool vector error."""
    dh_sigma_angle: float = np.radians(0.02)
    """Std of the DH angle errors."""
    encoder_max: float = 20 * ARCSEC
    """Largest harmonic amplitude of the encoder errors."""
    encoder_axes: tuple[int, ...] | None = None
    """Axes with encoder errors (None: all)."""
    step_deg: float = STEP_DEG
    """Node step of the maps."""
    rtest_max: float = 15e-6
    """Largest sphere displacement in its seat."""
    sigma_rtest: float = SIGMA_RTEST
    """R-Test reading noise (per coordinate)."""
    sigma_location: float = SIGMA_LOCATION
    """Error of the measured R-Test zero positions (per coordinate)."""
    compliance: dict[int, float] = field(default_factory=lambda: {2: 4e-6, 4: 6e-6})
    """Axis -> joint compliance in rad/(N m) (used with ``compliance``)."""
    thermal_alpha: float = 11e-6
    """Thermal expansion coefficient, 1/K (used with ``thermal``)."""
    temperature: tuple[float, float] = (20.0, 24.0)
    """Arm temperature range over the campaign, deg C; 20 deg C is the reference."""
    backlash: dict[int, float] = field(default_factory=lambda: {2: 6 * ARCSEC})
    """Axis -> half backlash in rad (used with ``backlash``)."""
    lateral_compliance: dict[int, tuple[float, float]] = field(
        default_factory=lambda: {1: (3e-5, 2e-5), 3: (2e-5, 4e-5), 10: (4e-5, 3e-5)})
    """Axis -> lateral compliance (kx, ky) about the joint's two lateral axes, rad/(N m) (used
    with ``lateral_compliance``; the default: the torso axis and the shoulder pitch of each arm
    of ``urdf/torso.urdf``, 0.3-1 mrad under their 10-40 N m; axes beyond the arm's are left
    out)."""
    crosstalk: dict[tuple[int, int], tuple[float, float]] = field(
        default_factory=lambda: {(4, 3): (6 * ARCSEC, -4 * ARCSEC)})
    """(axis, source) -> (c, s): the axis' angle error c cos + s sin of the source's angle, rad
    (used with ``crosstalk``; the default: A4 <- A3, 6 and -4 arcsec)."""
    points: int = 0
    """Tool points measured by an instrument (> 0: a points campaign, :func:`simulate_points`)."""
    sigma_point: float = SIGMA_POINT
    """Instrument noise of a point, per coordinate, m (used with ``points``)."""

    def __post_init__(self) -> None:
        unknown = [e for e in self.effects if e not in EFFECTS]
        if unknown:
            raise ValueError(f"effects: unknown {unknown}; choose from {', '.join(EFFECTS)}")


class TrueArm:
    """The virtual arm: nominal model + truth parameters + extra effects (forward only)."""

    def __init__(self, arm: Arm, truth: Parameters, config: SimulationConfig):
        self.arm, self.truth, self.config = arm, truth, config
        self._model = arm.runtime_model(truth.dh, truth.tool)
        self._data = self._model.createData()
        self._joints = JointKinematics(arm, truth)  # the IK's positions and joint Jacobian only

    def angle_offsets(self, q_readout: np.ndarray, direction: np.ndarray | None = None
                      ) -> np.ndarray:
        """Return the joint angle errors of the effects beyond the maps, shape (N, n_axes), rad.

        ``direction`` (N, n_axes) is each axis' direction of motion (backlash); None takes it from
        consecutive rows of ``q_readout``.
        """
        cfg, out = self.config, np.zeros_like(q_readout)
        if "compliance" in cfg.effects and self.arm.couplings:  # coupled configuration
            tau = gravity_torques(self.arm, self._model, q_readout)
            for axis, k in cfg.compliance.items():
                out[:, axis - 1] += k * tau[:, axis - 1]
        elif "compliance" in cfg.effects:
            for i, q in enumerate(q_readout):
                tau = -pin.computeGeneralizedGravity(self._model, self._data, q)  # by gravity
                for axis, k in cfg.compliance.items():
                    out[i, axis - 1] += k * tau[axis - 1]  # the joint gives way: the arm sags
        if "backlash" in cfg.effects:
            if direction is None:
                direction = motion_direction(q_readout)
            for axis, half in cfg.backlash.items():
                out[:, axis - 1] += half * direction[:, axis - 1]
        return out

    def adjustment(self, q_readout: np.ndarray, offsets: np.ndarray) -> Adjustment:
        """Return the truth's extension terms' change of the arm at the readouts.

        E.g. lateral compliance, at the readouts' gravity moments, with the other effects' angle
        errors ``offsets`` (N, n_axes) added.
        """
        change = adjustment(self.truth, Samples(self.arm, q_readout), self.arm.n_axes)
        change.offsets += offsets
        return change

    def _position_jacobian(self, q_readout: np.ndarray, temp: np.ndarray | None,
                           direction: np.ndarray | None, tool: ToolIndex = None
                           ) -> tuple[np.ndarray, np.ndarray]:
        """Return true r-CS positions (N, 3) and d(position)/d(readouts) (N, 3, n_axes).

        The joint columns only (:class:`~aacmm_pin.model.kinematics.JointKinematics`): no DH,
        tool or map columns.
        """
        offsets = self.angle_offsets(q_readout, np.zeros_like(q_readout) if direction is None
                                     else direction)
        if self.truth.extensions or self.arm.couplings:  # extensions at the readouts; a coupled
            # joint's angle errors as offsets (its readout is not read)
            pos, jac = self._joints.position_jacobian(q_readout, tool,
                                                      self.adjustment(q_readout, offsets))
        else:
            pos, jac = self._joints.position_jacobian(q_readout + offsets, tool)
        if "thermal" in self.config.effects and temp is not None:
            pos = pos * (1.0 + self.config.thermal_alpha * (temp - REFERENCE_TEMPERATURE_C))[:, None]
        return pos, jac

    def positions(self, q_readout: np.ndarray, temp: np.ndarray | None, frame: str = "r",
                  tool: ToolIndex = None) -> np.ndarray:
        """Return the true stylus centres, shape (N, 3), m, in the r-CS or the MT-CS."""
        offsets = self.angle_offsets(q_readout)
        if self.truth.extensions or self.arm.couplings:
            p_r = kinematics.stylus_positions(self.arm, self.truth, q_readout, frame="r", tool=tool,
                                              adjust=self.adjustment(q_readout, offsets))
        else:
            p_r = stylus_positions(self.arm, self.truth, q_readout + offsets, frame="r", tool=tool)
        if "thermal" in self.config.effects and temp is not None:
            p_r = p_r * (1.0 + self.config.thermal_alpha * (temp - REFERENCE_TEMPERATURE_C))[:, None]
        if frame == "r":
            return p_r
        p_mt: np.ndarray = p_r @ self.truth.rotation().T + self.truth.translation
        return p_mt

    def solve_ik(self, targets: np.ndarray, rng: np.random.Generator, temp: np.ndarray | None,
                 iterations: int = 25, starts: np.ndarray | None = None) -> np.ndarray:
        """Return readouts (N, n_axes) putting the true stylus on each target (N, 3) in the r-CS.

        Random starts within the joint limits (or within ``starts``, shape (n_axes, 2), rad, to
        favour a posture family), damped Newton steps projected on the limits, restarts for the
        samples that do not reach the target to 1e-12 m. With backlash, the postures are found
        without it, then refined from there with the directions of motion of that sequence.
        """
        q = self.arm.fill_readouts(self._solve_ik(targets, rng, temp, iterations, starts, None,
                                                  None))
        if "backlash" not in self.config.effects:
            return q
        for _ in range(3):  # directions follow the sequence; a few passes until they settle
            direction = motion_direction(q)
            q = self.arm.fill_readouts(self._solve_ik(targets, rng, temp, iterations, starts,
                                                      direction, q))
            if np.array_equal(motion_direction(q), direction):
                break
        return q

    def _solve_ik(self, targets: np.ndarray, rng: np.random.Generator, temp: np.ndarray | None,
                  iterations: int, starts: np.ndarray | None, direction: np.ndarray | None,
                  q_init: np.ndarray | None) -> np.ndarray:
        def position_jacobian(q: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return self._position_jacobian(q, None if temp is None else temp[rows],
                                           None if direction is None else direction[rows])

        return solve_ik(position_jacobian, targets, self.arm.joint_limits, rng, iterations,
                        starts, q_init)


def random_truth(arm: Arm, config: SimulationConfig, rng: np.random.Generator) -> Parameters:
    """Draw the virtual arm's parameters (DH, tool, X0, maps) for the effects switched on."""
    dh = arm.nominal_errors
    tool = arm.nominal_tool.copy()
    if "dh" in config.effects:
        for frame in arm.error_frames:
            sigma = config.dh_sigma_angle if frame.is_angle else config.dh_sigma_length
            dh[frame.name] += rng.normal(0.0, sigma)
        tool = tool + rng.normal(0.0, config.dh_sigma_length, 3)
    maps: dict[int, EncoderMap] = {}
    if "encoder" in config.effects:
        nodes = node_angles(config.step_deg)
        for axis in config.encoder_axes or arm.measured_axes:  # a coupled joint has no encoder
            values = np.zeros_like(nodes)
            for harmonic in (1, 2, 3, 4, 8):
                amp = rng.uniform(0.2, 1.0) * config.encoder_max / (1 if harmonic == 1 else 2)
                values += amp * np.sin(harmonic * nodes + rng.uniform(0, 2 * np.pi))
            maps[axis] = EncoderMap(values, config.step_deg)
    tools = {}
    if arm.n_tools > 1:  # a tree: every tool's vector (drawn after the rest: same draws before)
        tools = {joint: vector + (rng.normal(0.0, config.dh_sigma_length, 3)
                                  if "dh" in config.effects else 0.0)
                 for joint, vector in arm.nominal_tools.items()}
        tool = next(iter(tools.values()))
    extensions = {}
    if "lateral_compliance" in config.effects:
        extensions = {f"lateral_compliance[A{a}]": np.asarray(k, dtype=float)
                      for a, k in sorted(config.lateral_compliance.items()) if a <= arm.n_axes}
    if "crosstalk" in config.effects:
        extensions |= {f"crosstalk[A{a}<-A{b}]": np.asarray(cs, dtype=float)
                       for (a, b), cs in sorted(config.crosstalk.items())
                       if max(a, b) <= arm.n_axes}
    return Parameters(arm=arm.name, dh=dh, tool=tool,
                      rotation_abc=rng.normal(0.0, config.rotation_sigma, 3),
                      translation=np.asarray(config.mt_translation, dtype=float),
                      encoder_maps=maps, step_deg=config.step_deg, tools=tools,
                      extensions=extensions)


def _bar_sockets(rng: np.random.Generator, n: int) -> list[dict[str, np.ndarray]]:
    """Return n bar placements (socket -> r-CS position) on the table around the arm.

    As in the paper's Figs. 7-8: the bar lies on the worktable (socket A 0.3-0.45 m from A1, at
    0-50 mm above the base, the bar within +-6 deg of horizontal), at azimuths spread around the arm.
    """
    out = []
    for k in range(n):
        azimuth = -2.4 + 4.8 * (k + rng.uniform(0.2, 0.8)) / n
        radius = rng.uniform(0.3, 0.45)
        a = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth), rng.uniform(0.0, 0.05)])
        heading = azimuth + rng.uniform(-0.8, 0.8)
        u = np.array([np.cos(heading), np.sin(heading), rng.uniform(-0.1, 0.1)])
        u /= np.linalg.norm(u)
        sockets = {"A": a}
        for (_, to), length in BAR_LENGTHS.items():
            sockets[to] = a + length * u
        out.append(sockets)
    return out


@dataclass(frozen=True)
class Simulation:
    """A simulated campaign and its truth."""

    campaign: Campaign
    """What a user would record (noisy, in the documented format once written)."""
    truth: Parameters
    """The virtual arm; ``truth.extra['effects']`` lists the effects and their values."""
    sphere_mt: np.ndarray
    """True sphere centre of every SPAT sample in the MT-CS (of a points campaign: every true
    tool point in the instrument frame), shape (N, 3), m."""
    sockets_r: dict[int, dict[str, np.ndarray]]
    """True socket positions in the r-CS: placement -> socket -> (3,), m."""


def simulate_spat(true_arm: TrueArm, p0: np.ndarray, n: int, rng: np.random.Generator,
                  temp: np.ndarray | None = None, starts: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulate one SPAT of n samples at the R-Test nest whose true zero position is p0 (MT-CS).

    Returns:
        ``(q, sphere, displacement)``: readouts (n, n_axes) rad as written to file, true sphere
        centres (n, 3) m in the MT-CS, measured R-Test displacements (n, 3) m (with noise).
    """
    config, truth = true_arm.config, true_arm.truth
    disp = np.zeros((n, 3))
    if "rtest" in config.effects:  # sphere pushed in its seat, mostly sideways
        direction = rng.normal(size=(n, 3)) * [1.0, 1.0, 0.3]
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        disp = config.rtest_max * rng.uniform(0, 1, (n, 1)) ** 0.5 * direction
    target_r = (p0 + disp - truth.translation) @ truth.rotation()
    q = true_arm.solve_ik(target_r, rng, temp, starts=starts)
    q = np.radians(np.round(np.degrees(q), 9))  # as written to file: truth follows the file
    sphere = true_arm.positions(q, temp, frame="mt")
    return q, sphere, sphere - p0 + rng.normal(0.0, config.sigma_rtest, (n, 3))


def simulate_points(arm: Arm, config: SimulationConfig) -> Simulation:
    """Simulate tool points measured by one instrument (tracker, motion capture) in its own frame.

    ``config.points`` poses drawn uniformly within the joint limits, the arm's tools measured
    alternately (``tool`` column), each point with the instrument's noise ``config.sigma_point``
    per coordinate; the instrument frame is X0 and the translation of the truth. No SPAT, no bar.
    """
    rng = np.random.default_rng(config.seed)
    truth = random_truth(arm, config, rng)
    true_arm = TrueArm(arm, truth, config)
    lim = arm.joint_limits
    q = arm.fill_readouts(rng.uniform(lim[:, 0], lim[:, 1], (config.points, arm.n_axes)))
    q = np.radians(np.round(np.degrees(q), 9))  # as written to file: truth follows the file
    tool = np.array(arm.tool_names)[np.arange(config.points) % arm.n_tools]
    p_r = true_arm.positions(q, None, tool=tool)
    point_mt = p_r @ truth.rotation().T + truth.translation
    measured = point_mt + rng.normal(0.0, config.sigma_point, point_mt.shape)
    points = PointLog(group=np.ones(config.points, dtype=np.int64), q=q, point=measured,
                      tool=tool if arm.n_tools > 1 else None)
    campaign = Campaign(spat=None, locations={}, lengthbar=None, bar={}, source=None,
                        points=points)
    return Simulation(campaign, truth.replace(extra={"effects": _truth_record(config, {})}),
                      point_mt, {})


def _truth_record(config: SimulationConfig, locations_true: dict[int, np.ndarray]
                  ) -> dict[str, Any]:
    """Return what ``truth.json`` records under ``effects`` (the effects and their values)."""
    effects: dict[str, Any] = {"seed": config.seed, "switched_on": list(config.effects)}
    if "encoder" in config.effects:
        effects["encoder"] = "node tables above"
    if "rtest" in config.effects:
        effects["rtest_max_um"] = config.rtest_max * 1e6
    if config.points:
        effects["points"] = config.points
        effects["sigma_point_um"] = config.sigma_point * 1e6
    else:
        effects["sigma_rtest_um"] = config.sigma_rtest * 1e6
        effects["sigma_location_um"] = config.sigma_location * 1e6
        effects["locations_true_mm"] = {str(m): (p * 1e3).tolist()
                                        for m, p in locations_true.items()}
    if "compliance" in config.effects:
        effects["compliance_rad_per_nm"] = {str(a): k for a, k in config.compliance.items()}
    if "thermal" in config.effects:
        effects["thermal_alpha_per_k"] = config.thermal_alpha
        effects["thermal_reference_c"] = REFERENCE_TEMPERATURE_C
    if "backlash" in config.effects:
        effects["backlash_half_rad"] = {str(a): b for a, b in config.backlash.items()}
    if "lateral_compliance" in config.effects:
        effects["lateral_compliance"] = "extensions (kx, ky in rad per N m)"
    if "crosstalk" in config.effects:
        effects["crosstalk"] = "extensions (cos, sin amplitudes in rad)"
    return effects


def simulate_campaign(arm: Arm, config: SimulationConfig | None = None) -> Simulation:
    """Simulate a SPAT + length-bar campaign on a virtual version of ``arm``.

    With ``config.points`` > 0, a campaign of instrument points instead (:func:`simulate_points`).
    """
    config = config or SimulationConfig()
    if config.points:
        return simulate_points(arm, config)
    rng = np.random.default_rng(config.seed)
    truth = random_truth(arm, config, rng)
    true_arm = TrueArm(arm, truth, config)
    thermal = "thermal" in config.effects

    def temps(n: int) -> np.ndarray | None:
        return np.sort(rng.uniform(*config.temperature, n)) if thermal else None

    locations_true = {m + 1: np.array([x, y, rng.uniform(0.0, 0.01)])
                      for m, (x, y) in enumerate(config.location_xy)}
    loc_col, q_all, disp_all, sphere_all = [], [], [], []
    temp_all: list[np.ndarray] = []
    for m, p0 in locations_true.items():
        temp = temps(config.samples_per_location)
        q, sphere, disp = simulate_spat(true_arm, p0, config.samples_per_location, rng, temp)
        loc_col.append(np.full(len(q), m))
        q_all.append(q)
        sphere_all.append(sphere)
        disp_all.append(disp)
        if temp is not None:
            temp_all.append(temp)
    n_spat = sum(len(c) for c in loc_col)
    if "backlash" in config.effects:  # directions run on across locations: the sphere follows
        q_cat = np.concatenate(q_all)
        sphere_new = true_arm.positions(q_cat, np.concatenate(temp_all) if thermal else None, "mt")
        split = np.cumsum([len(q) for q in q_all])[:-1]
        disp_all = [d - s + n for d, s, n in zip(disp_all, sphere_all, np.split(sphere_new, split))]
        sphere_all = np.split(sphere_new, split)
    spat = SpatLog(location=np.concatenate(loc_col), q=np.concatenate(q_all),
                   displacement=np.concatenate(disp_all),
                   t=np.arange(n_spat) * 0.1 if ("backlash" in config.effects or thermal) else None,
                   temp=np.concatenate(temp_all) if thermal else None, lines=None)
    measured_locations = {m: p + rng.normal(0.0, config.sigma_location, 3)
                          for m, p in locations_true.items()}
    sockets = {k + 1: s for k, s in enumerate(_bar_sockets(rng, config.bar_placements))}
    placement, socket, q_bar = [], [], []
    t_bar: list[np.ndarray] = []
    targets = []
    for k, by_socket in sockets.items():
        for name, pos in by_socket.items():
            n = config.samples_per_socket
            temp = temps(n)
            targets.append(np.tile(pos, (n, 1)))
            if config.sigma_socket > 0:  # drawn only then: other campaigns stay as they were
                targets[-1] = targets[-1] + rng.normal(0.0, config.sigma_socket, (n, 3))
            if "backlash" not in config.effects:
                q_bar.append(true_arm.solve_ik(targets[-1], rng, temp))
            placement.append(np.full(n, k))
            socket += [name] * n
            if temp is not None:
                t_bar.append(temp)
    if "backlash" in config.effects and targets:  # one motion sequence over the whole bar log
        q_bar = [true_arm.solve_ik(np.concatenate(targets), rng,
                                   np.concatenate(t_bar) if thermal else None)]
    lengthbar = None if not q_bar else LengthBarLog(
        placement=np.concatenate(placement), socket=np.array(socket),
        q=np.radians(np.round(np.degrees(np.concatenate(q_bar)), 9)),
        t=None, temp=np.concatenate(t_bar) if thermal else None, lines=None)
    truth = truth.replace(extra={"effects": _truth_record(config, locations_true)})
    campaign = Campaign(spat=spat, locations=measured_locations, lengthbar=lengthbar,
                        bar=dict(BAR_LENGTHS) if lengthbar is not None else {}, source=None)
    return Simulation(campaign, truth, np.concatenate(sphere_all), sockets)
