"""``python -m ase_maud``: the ``ase-maud`` command."""

import sys

from ase_maud.cli.command import main

sys.exit(main())
