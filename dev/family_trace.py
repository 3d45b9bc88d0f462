"""Where a default Maud run on a family scene (:data:`ase_maud.scenes.families.FAMILIES`)
spends its steps: per step the energy, the largest force, its point's distance in springs
from the nearest held point (one with no free coordinate), the participation ratio of the forces
``(sum |f_i|^2)^2 / sum |f_i|^4`` (how many points carry them), the longest move and the
move of the point of the largest force; at the steps ``--blocks`` the Hessian's own 3x3
block (its eigenvalues) at the ``--top`` points of the largest forces and at the point
farthest from the held ones, beside the springs model's ``Q L_ii``::

    NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python dev/family_trace.py --family saddle_dome --seed 0 --sizes 40000 50000 \\
        --crossover 100000000 --blocks 250 --out trace.csv

Rows are printed and written to ``--out`` (a CSV, never replaced); the blocks are printed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra

from ase_maud import Maud
from ase_maud.bench.report import write_csv
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.families import FAMILIES

FIELDS = ['step', 'energy', 'fmax', 'hops_to_held', 'participation', 'longest_move',
          'move_at_fmax']


def block_eigenvalues(atoms, point: int) -> np.ndarray:
    """Eigenvalues of the Hessian's 3x3 block of ``point`` (energy per length squared)."""
    potential = atoms.calc.potential
    unit = np.zeros((3, len(atoms), 3))
    unit[[0, 1, 2], point, [0, 1, 2]] = 1.0
    block = potential.hvp(atoms.positions, unit)[:, point, :]
    return np.linalg.eigvalsh(0.5 * (block + block.T))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--family', required=True, choices=sorted(FAMILIES))
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--sizes', nargs=2, type=int, default=[300, 3000])
    parser.add_argument('--crossover', type=int, default=None)
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--blocks', nargs='*', type=int, default=[])
    parser.add_argument('--top', type=int, default=3)
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args(argv)
    if args.out.exists():
        sys.exit(f'{args.out} exists: not replaced')
    atoms = FAMILIES[args.family](args.seed, tuple(args.sizes))
    if args.crossover is not None:
        atoms.calc.set(crossover=args.crossover)
    potential = atoms.calc.potential
    laplacian = potential.Q * potential.spring_laplacian(len(atoms))
    held = np.flatnonzero(~free_dofs(atoms, potential.dim).any(axis=1))   # no free coordinate
    hops = (dijkstra(abs(laplacian.tocsr()), indices=held, unweighted=True,
                     min_only=True) if len(held) else np.full(len(atoms), np.inf))
    opt = Maud(atoms, logfile=None)
    last = atoms.positions.copy()
    rows = []

    def record():
        nonlocal last
        forces = atoms.get_forces()
        square = (forces**2).sum(axis=1)
        point = int(np.argmax(square))
        move = np.linalg.norm(atoms.positions - last, axis=1)
        last = atoms.positions.copy()
        row = {'step': opt.nsteps, 'energy': f'{atoms.get_potential_energy():.6f}',
               'fmax': f'{np.sqrt(square[point]):.3e}', 'hops_to_held': hops[point],
               'participation': f'{square.sum()**2 / (square**2).sum():.0f}',
               'longest_move': f'{move.max():.3e}', 'move_at_fmax': f'{move[point]:.3e}'}
        print(' '.join(str(row[key]) for key in FIELDS), flush=True)
        rows.append(row)
        if opt.nsteps in args.blocks:
            far = int(np.argmax(np.where(np.isfinite(hops), hops, -1)))
            for p in [*np.argsort(square)[-args.top:], far]:
                print(f'  step {opt.nsteps} point {p} ({hops[p]:.0f} springs from the held): '
                      f'block eigenvalues {np.round(block_eigenvalues(atoms, p), 3)}, '
                      f'springs {laplacian[p, p]:.3f}', flush=True)

    opt.attach(record)
    opt.run(fmax=args.fmax, steps=args.steps)
    write_csv(args.out, rows)


if __name__ == '__main__':
    main()
