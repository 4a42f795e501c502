"""Outputs: the calibration folder, figures, the MeshCat viewer, the demo."""
