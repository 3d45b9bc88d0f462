"""How well the springs model and the factorised near-field model
(:mod:`ase_maud.optimize.models.near_lu`) match the Hessian, on small repulsion-dominated
scenes: the generalised eigenvalues of ``H v = lambda P v`` on the internal
moves (free degrees of freedom, rigid motions projected out), at the start
and at a minimum (relaxed by Maud to ``--fmax``). Their spread (condition
number of ``P^-1 H``) bounds how many steps a method preconditioned by ``P``
needs; a ``P`` that is not positive definite is marked. Dense, for a few
hundred points::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python dev/repulsion_spectrum.py --out docs/dev/bench/repulsion/spectrum.md
"""

from __future__ import annotations

import argparse
import datetime
import runpy
import sys
from pathlib import Path

import numpy as np
import scipy.linalg

from ase_maud import Maud
from ase_maud.optimize.models.near_lu import NearLUModel
from ase_maud.physics.dofs import free_dofs, rigid_body_modes

#: benchmarks/repulsion_models.py, for its scenes (``scene``: a catalogue scene or a compas net).
TOOL = runpy.run_path(str(Path(__file__).resolve().parents[1] / 'benchmarks'
                          / 'repulsion_models.py'))


def springs_matrix(atoms) -> np.ndarray:
    """The springs model's ``Q L (x) I`` (its floor shift aside) on the free DOFs."""
    keep = np.flatnonzero(free_dofs(atoms, atoms.calc.potential.dim).ravel())
    return atoms.calc.potential.spring_hessian(len(atoms)).toarray()[np.ix_(keep, keep)]


def row(spec: str, where: str, atoms, cutoffs: list[float]) -> tuple[str, list[str]]:
    """One table row at ``atoms``' positions, and the models' names."""
    dim = atoms.calc.potential.dim
    free = free_dofs(atoms, dim)
    keep = np.flatnonzero(free.ravel())
    rigid = rigid_body_modes(atoms.positions, free, dim)
    basis = scipy.linalg.null_space(rigid.T) if rigid.size else np.eye(len(keep))
    hessian = basis.T @ atoms.calc.potential.hessian(atoms.positions)[np.ix_(keep, keep)] @ basis
    negative = int((np.linalg.eigvalsh(hessian) < 0).sum())
    models = {'springs': springs_matrix(atoms)}
    for cutoff in cutoffs:
        models[f'near {cutoff:g}'] = NearLUModel(cutoff=cutoff).matrix(atoms).toarray()
    cells = []
    for matrix in models.values():
        inner = basis.T @ matrix @ basis
        values = np.linalg.eigvalsh(inner)
        if values.min() <= 0:
            cells.append(f'indefinite ({int((values < 0).sum())} < 0)')
            continue
        lam = scipy.linalg.eigh(hessian, inner, eigvals_only=True)
        if lam.min() <= 0:
            cells.append(f'[{lam.min():.3g}, {lam.max():.3g}]')
        else:
            cells.append(f'{lam.max() / lam.min():.3g}')
    text = f'| {spec} | {where} | {len(basis.T)} | {negative} | ' + ' | '.join(cells) + ' |'
    return text, list(models)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=['neighbour_graph:300', 'all_pairs:100',
                                                        'compas:mesh_100_faces.json',
                                                        'hub_net:12'])
    parser.add_argument('--cutoffs', nargs='+', type=float, default=[0.0, 1.5, 2.5])
    parser.add_argument('--fmax', type=float, default=1e-5)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    lines = []
    for spec in args.scenes:
        atoms, unit = TOOL['scene'](spec)
        for where in ('start', 'minimum'):
            if where == 'minimum':
                Maud(atoms, logfile=None).run(fmax=args.fmax * unit, steps=5000)
            text, names = row(spec, where, atoms, args.cutoffs)
            lines.append(text)
            print(text, flush=True)
    head = [f'Measured {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, one thread: '
            f'`python dev/repulsion_spectrum.py {" ".join(sys.argv[1:])}`', '',
            'Condition number of `P^-1 H` on the internal moves (or the range of its '
            'eigenvalues where `H` has negative ones; "indefinite": `P` itself is)', '',
            '| scene | where | internal moves | H < 0 | ' + ' | '.join(names) + ' |',
            '|' + '---|' * (4 + len(names))]
    text = '\n'.join(head + lines) + '\n'
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)


if __name__ == '__main__':
    main()
