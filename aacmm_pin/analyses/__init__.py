"""Analyses of a calibration: validation, uncertainty, planning, discovery, the residual scan,
simulation and ISO 10360.
"""
