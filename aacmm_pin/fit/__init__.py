"""The fit: measurements and noise policy, unknowns, the solver, identifiability, identification, robust fitting."""
