"""The ``ase-maud`` command: :func:`main` and its parser
(:mod:`~ase_maud.cli.command`), one module per command (``relax``, ``show``,
``classify``, ``saddles``, ``bench`` and ``backends``) and the options they
share (:mod:`~ase_maud.cli.options`).
"""

from ase_maud.cli.command import build_parser, main
from ase_maud.old_paths import old_names

__all__ = ['main', 'build_parser']
#: The names of ase_maud 0.1's ``ase_maud.cli`` module, handed on with a warning.
__getattr__ = old_names('cli')
