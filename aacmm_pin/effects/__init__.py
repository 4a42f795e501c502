r"""The effect library: named extensions of the arm model, for :func:`aacmm_pin.discover`.

An effect (:class:`Effect`) is a physical cause of measurement error; it proposes terms
(:class:`Term`), each a few parameters that the model is linear in, acting in one of a few ways
(one subclass each: :class:`AngleTerm`, :class:`ScaleTerm`, :class:`TiltTerm`,
:class:`FrameTerm`, :class:`MeasurementTerm`, :class:`MapTerm`; see :mod:`aacmm_pin.effects.base`).

Built-in effects (one module each): ``encoder`` (map or low-order harmonics), ``compliance``
(gravity torque about the joint axis, from the URDF inertias), ``lateral_compliance`` (gravity
torque about the two axes perpendicular to a joint's), ``thermal`` (``temp_c``), ``backlash``
(direction of motion), ``crosstalk`` (angle of a neighbouring axis), ``rtest`` (the sphere moving
in its seat) and ``tool`` (in every start model). Add your own with :func:`register_effect`, from
an installed package's ``aacmm_pin.effects`` entry point, or from a file
(:func:`load_effect_file`, ``--effects-file`` on the command line); see
:mod:`aacmm_pin.effects.registry`.

Calibrated values of the terms live in ``Parameters.extensions`` (``parameters.json``
``"extensions": {"compliance[A2]": [k], ...}``, SI units), each key's term in
``Parameters.extension_terms`` (looked up once, where the parameters are made), and are applied by
:func:`aacmm_pin.stylus_positions` and :func:`aacmm_pin.predict` (:mod:`aacmm_pin.effects.forward`).
The file with its terms and plugins is :mod:`aacmm_pin.effects.parameters_file`.
"""

from aacmm_pin.effects.base import (
    Adjustment,
    AngleTerm,
    BasisTerm,
    Effect,
    FrameTerm,
    MapTerm,
    MeasurementTerm,
    ModelSpec,
    ScaleTerm,
    StylusDerivatives,
    Term,
    TiltTerm,
    Variable,
)
from aacmm_pin.effects.builtin.backlash import backlash
from aacmm_pin.effects.builtin.compliance import compliance
from aacmm_pin.effects.builtin.crosstalk import crosstalk
from aacmm_pin.effects.builtin.encoder import encoder_harmonic, encoder_map
from aacmm_pin.effects.builtin.lateral_compliance import lateral_compliance
from aacmm_pin.effects.builtin.rtest import rtest
from aacmm_pin.effects.builtin.thermal import thermal
from aacmm_pin.effects.forward import measurement_shift
from aacmm_pin.effects.parameters_file import check_extensions, read_parameters, write_parameters
from aacmm_pin.effects.registry import (
    LIBRARY,
    EffectNotFound,
    effect_names,
    library,
    load_effect_file,
    load_plugins,
    plugin_of,
    plugins_of,
    register_effect,
    term_from_key,
    terms_of,
)

__all__ = [
    "LIBRARY", "Adjustment", "AngleTerm", "BasisTerm", "Effect", "EffectNotFound", "FrameTerm", "MapTerm",
    "MeasurementTerm", "ModelSpec", "ScaleTerm", "StylusDerivatives", "Term", "TiltTerm", "Variable",
    "backlash", "check_extensions", "compliance", "crosstalk", "effect_names", "encoder_harmonic",
    "encoder_map", "lateral_compliance", "library", "load_effect_file", "load_plugins",
    "measurement_shift", "plugin_of", "plugins_of", "read_parameters", "register_effect", "rtest",
    "term_from_key", "terms_of", "thermal", "write_parameters",
]
