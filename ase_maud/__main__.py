"""``python -m ase_maud``: the ``ase-maud`` command."""

import sys

from .cli import main

sys.exit(main())
