"""The built-in effects, one module each (their term constructors are re-exported by aacmm_pin.effects)."""
