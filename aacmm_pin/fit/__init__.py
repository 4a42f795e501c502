"""The fit: measurements, unknowns, the solver, identifiability, identification, robust fits."""
