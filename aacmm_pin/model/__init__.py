"""The arm model: URDF, error frames, kinematics, encoder maps, parameters, sizes, samples."""
