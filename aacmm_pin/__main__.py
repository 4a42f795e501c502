"""``python -m aacmm_pin`` runs the ``aacmm-pin`` command."""

from aacmm_pin.cli import run

run()
