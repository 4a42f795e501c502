"""Sphinx configuration: the guide pages (Markdown, MyST) and the API reference from the docstrings.

Build: ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (``.ci/run`` does, warnings
as errors). Needs the ``docs`` extra: ``pip install ".[docs]"``.
"""

from __future__ import annotations

import sys
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's package, whatever is installed

# ``python -m aacmm_pin`` runs the command line on import: the API reference shows a stand-in.
for _main in ("aacmm_pin.__main__", "aacmm_pin.cli.__main__"):
    sys.modules[_main] = types.ModuleType(_main, "``python -m`` entry point: :func:`aacmm_pin.cli.main`.")

import aacmm_pin  # noqa: E402 (after the path and the stand-ins)

project = "aacmm_pin"
author = "aacmm_pin authors"
copyright = "2026, aacmm_pin authors"
release = aacmm_pin.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build"]
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 3

autosummary_generate = True
templates_path = ["_templates"]
autodoc_member_order = "bysource"
autodoc_typehints = "description"
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# A short type name in a signature that two modules define (``Problem``: errors.Problem and
# fit.solver.Problem) links to the first; Sphinx's "more than one target" is not a docstring error.
suppress_warnings = ["ref.python"]

html_theme = "alabaster"
html_static_path: list[str] = []


_AS_WRITTEN: dict[str, list[str]] = {}


def _keep_attribute_docstring(app, what, name, obj, options, lines):
    """Remember an attribute's docstring before napoleon reads it.

    Napoleon reads an attribute docstring's first line ``X: Y`` as type ``X``, description ``Y``;
    this package's attribute docstrings are sentences ("Samples kept in the fit, shape (N,), bool;
    None: all."), whose type is the annotation: they are shown as written.
    """
    if what in ("attribute", "data", "property"):
        _AS_WRITTEN[name] = list(lines)


def _restore_attribute_docstring(app, what, name, obj, options, lines):
    """Put back the docstring remembered by :func:`_keep_attribute_docstring`."""
    if name in _AS_WRITTEN:
        lines[:] = _AS_WRITTEN.pop(name)


def setup(app):
    """Around napoleon (priority 500) on every docstring."""
    app.connect("autodoc-process-docstring", _keep_attribute_docstring, priority=100)
    app.connect("autodoc-process-docstring", _restore_attribute_docstring, priority=900)
