"""``python -m aacmm_pin.cli`` runs the ``aacmm-pin`` command."""

import sys

from aacmm_pin.cli import main

sys.exit(main())
