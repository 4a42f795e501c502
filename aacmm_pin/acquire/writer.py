"""Crash-safe writing of SPAT rows into a campaign folder, as they are acquired.

The writer lives with the campaign's other writers, :mod:`aacmm_pin.data.campaign_writer` (one
module writes ``spat.csv``); this module keeps its import path.
"""

from __future__ import annotations

from aacmm_pin.data.campaign_writer import LOCATION_COLUMNS, SpatWriter, spat_columns, write_zero

__all__ = ["LOCATION_COLUMNS", "SpatWriter", "spat_columns", "write_zero"]
