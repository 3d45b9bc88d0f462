"""``ase-maud classify``: minimum, saddle of index k, or not stationary.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from ase_maud.cli.options import judging_fmax, net_options, set_net_tables

if TYPE_CHECKING:
    pass


def describe(point) -> str:
    """The verdict of a :class:`~ase_maud.analysis.stationary.StationaryPoint` in words:
    'minimum', 'saddle of index k', 'maximum' or 'degenerate (...)', after
    'not stationary; the curvature there: ' if it is not stationary."""
    verdict = {'saddle': f'saddle of index {point.index}',
               'degenerate': f'degenerate ({point.n_zero} zero modes, '
                             f'{point.n_negative} negative)'}.get(point.verdict, point.verdict)
    if not point.stationary:
        verdict = f'not stationary (fmax {point.fmax:.3g}); the curvature there: {verdict}'
    return verdict


def classify_command(args: argparse.Namespace) -> int:
    """``ase-maud classify``: exit status 0 if stationary, else 1. Stationary
    means fmax at most ``--fmax``, by default the fmax a trajectory was
    relaxed to, else analysis's default (:func:`judging_fmax`)."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.analysis.stationary import classify as classify_point
    from ase_maud.io.nets import read_net

    atoms = read_net(args.file, index=args.frame, **net_options(args))
    set_net_tables(atoms, args)
    ftol, why = judging_fmax(args)
    with warnings.catch_warnings():   # "not stationary" is said below
        warnings.simplefilter('ignore', UserWarning)
        point = classify_point(atoms, k=args.k, ftol=ftol)
    print(f'{describe(point)}: {Path(args.file).name} {len(atoms)} points, '
          f'{point.n_modes} free non-rigid modes ({point.n_fixed} fixed coordinates, '
          f'{point.n_rigid} rigid-body modes removed), fmax {point.fmax:.3g} '
          f'(stationary up to {point.ftol:.3g}, {why})')
    lowest = ' '.join(f'{value:.6g}' for value in point.eigenvalues[:args.k])
    print(f'lowest eigenvalues ({point.method}, units of Q): {lowest}')
    return 0 if point.stationary else 1
