"""A simulated campaign written as a folder: the campaign files, its truth and the true points.

:func:`~aacmm_pin.analyses.simulate.simulate_campaign` computes a :class:`Simulation`;
:func:`write_simulation` writes it through the data layer's writers
(:func:`~aacmm_pin.data.campaign_writer.write_campaign`,
:func:`~aacmm_pin.data.campaign_writer.write_points`) and the truth's parameter file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aacmm_pin.analyses.simulate import Simulation
from aacmm_pin.data.campaign_writer import write_campaign, write_points
from aacmm_pin.data.output_folder import output_folder
from aacmm_pin.model.parameters import write_parameters


def write_simulation(sim: Simulation, folder: str | Path, force: bool = False) -> None:
    """Write the campaign files, ``truth.json`` and the true points (``truth_*.csv``, mm).

    ``truth_spheres.csv`` and ``truth_sockets.csv`` for SPATs and the bar, ``truth_points.csv``
    for a points campaign.

    The folder is written whole (:func:`~aacmm_pin.data.output_folder.output_folder`).

    Raises:
        OutputExistsError: if ``folder`` holds files and not ``force``.
    """
    with output_folder(folder, force) as tmp:
        _write_simulation_files(sim, tmp)


def _write_simulation_files(sim: Simulation, folder: Path) -> None:
    """Write the files of :func:`write_simulation` into an existing folder."""
    write_campaign(sim.campaign, folder)
    write_parameters(sim.truth, folder / "truth.json")
    if sim.campaign.spat is None:  # instrument points: their true positions, instrument frame
        points = sim.campaign.points
        assert points is not None
        tools = points.tool.tolist() if points.tool is not None else [""] * len(points.q)
        write_points(folder / "truth_points.csv", sim.sphere_mt, keep={"tool": tools})
        return
    write_points(folder / "truth_spheres.csv", sim.sphere_mt,
                 keep={"location": [str(m) for m in sim.campaign.spat.location]})
    sockets = [(k, s, p) for k, by_socket in sim.sockets_r.items() for s, p in by_socket.items()]
    write_points(folder / "truth_sockets.csv", np.array([p for _, _, p in sockets]).reshape(-1, 3),
                 keep={"placement": [str(k) for k, _, _ in sockets],
                       "socket": [str(s) for _, s, _ in sockets]})
