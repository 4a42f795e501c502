"""Analyses of a calibration: validation, uncertainty, planning, discovery and the residual scan, simulation, ISO 10360."""
