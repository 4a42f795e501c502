"""``python -m aacmm_pin.cli`` runs the ``aacmm-pin`` command."""

from aacmm_pin.cli import run

run()
