"""``python -m aacmm_pin`` runs the ``aacmm-pin`` command."""

import sys

from aacmm_pin.cli import main

sys.exit(main())
