"""Analyses of a calibration: validation, uncertainty, planning, discovery, simulation, ISO 10360."""
