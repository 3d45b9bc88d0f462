"""Factorise or multigrid: the springs model's ``Q L`` on the free points of
nets and graphs of growing size, by SuperLU (the symmetric mode
``ase_maud.optimize.models.sparse.spd_inverse`` uses: minimum degree on ``A + A^T``, no
pivoting) and by pyamg's smoothed aggregation (CG to a relative residual of
1e-6); seconds to factorise (set up) and to solve for three coordinate
columns, and the factor's nonzeros. ``AMG_MIN_DOFS`` is chosen from it::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/spd_solvers.py \\
        --out docs/dev/bench/spd_solvers.md
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

import numpy as np
import pyamg
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ase_maud.physics.topology import fixed_atoms
from ase_maud.scenes.catalogue import build


def laplacian(name: str, size: int) -> sp.csc_matrix:
    """``L`` of a scene's springs on its free points (a shift of 1e-6 where
    nothing is fixed)."""
    atoms = build(name, size)
    matrix = atoms.calc.potential.spring_laplacian(len(atoms))
    free = ~fixed_atoms(atoms)
    matrix = matrix[free][:, free]
    if free.all():
        matrix = matrix + 1e-6 * sp.eye(matrix.shape[0])
    return sp.csc_matrix(matrix)


def timed(function):
    start = time.process_time()
    value = function()
    return value, time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=[
        'hanging_net:100', 'hanging_net:316', 'hanging_net:1000', 'hub_net:200',
        'disc:100000', 'random_graph:4000', 'neighbour_graph:100000'])
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    lines = [f'Measured {datetime.date.today()}, one thread, CPU seconds: '
             f'`python benchmarks/spd_solvers.py {" ".join(sys.argv[1:])}`', '',
             '| scene | free points | SuperLU factor s | factor nonzeros | solve 3 s '
             '| pyamg setup s | solve 3 s |', '|---|---|---|---|---|---|---|']
    for scene in args.scenes:
        name, size = scene.split(':')
        matrix = laplacian(name, int(size))
        rhs = np.random.default_rng(0).standard_normal((matrix.shape[0], 3))
        lu, factor = timed(lambda m=matrix: splu(m, permc_spec='MMD_AT_PLUS_A',
                                                 diag_pivot_thresh=0.0,
                                                 options={'SymmetricMode': True}))
        _, solve = timed(lambda lu=lu, rhs=rhs: lu.solve(rhs))
        hierarchy, setup = timed(lambda m=matrix: pyamg.smoothed_aggregation_solver(
            sp.csr_matrix(m)))
        _, multigrid = timed(lambda h=hierarchy, rhs=rhs: [
            h.solve(column, tol=1e-6, accel='cg') for column in rhs.T])
        row = (f'| {name} {size} | {matrix.shape[0]} | {factor:.3g} | '
               f'{lu.L.nnz + lu.U.nnz:.3g} | {solve:.3g} | {setup:.3g} | {multigrid:.3g} |')
        print(row, flush=True)
        lines.append(row)
    if args.out:
        args.out.write_text('\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
