"""The arm model: URDF, error frames, batched kinematics, encoder maps, parameters, plausible sizes, samples."""
