"""Which repulsion a large-scene model should hold: the springs model against
the alternatives the design weighed, with the same step rule, on the large
suite's scenes. Calls (and Hessian-vector products) and CPU seconds to
``--fmax`` (in ``Q a``), one thread::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/large_model_sweep.py --out docs/dev/bench/large_models.md

- ``springs``: ``Q L`` per coordinate, factorised once, L-BFGS memory 20 (the
  package's large-scene model);
- ``near signed`` / ``near positive``: ``Q (L (x) I) + R`` with ``R`` the
  repulsion's pair blocks within ``--cutoff`` nearest-neighbour distances,
  assembled with their couplings (a Laplacian of 3x3 blocks), as they are or
  each made positive, rebuilt and factorised (3N x 3N) at every step, same
  memory; a direction that is not downhill falls back to the springs model;
- ``newton-cg``: truncated Newton, each step CG on ``H d = f`` with exact
  Hessian-vector products, preconditioned by the springs model, stopped at a
  relative residual ``min(0.5, sqrt(|f|))`` or on negative curvature; no
  memory. Its products are counted beside the calls.
"""

from __future__ import annotations

import argparse
import datetime
import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

from ase_maud import Maud
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.counting import cpu_seconds
from ase_maud.optimize.models.base import Solver
from ase_maud.optimize.models.springs import SpringsModel
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.catalogue import LARGE, build


class NearField(SpringsModel):
    """The springs' Hessian plus the repulsion's near pair blocks, coupled."""


    def __init__(self, cutoff: float, positive: bool):
        super().__init__()
        self.cutoff, self.positive = cutoff, positive

    def at(self, atoms, learnt=None):
        springs = super().at(atoms, learnt)
        potential = atoms.calc.potential
        x = potential.reduced(atoms.positions)
        n, dim = len(x), potential.dim
        tree = cKDTree(x[:, :dim])
        spacing = np.median(tree.query(x[:, :dim], k=2)[0][:, 1])
        i, j = tree.query_pairs(self.cutoff * spacing, output_type='ndarray').T
        blocks = potential.Q * physics.repulsion_block(x[i, :dim] - x[j, :dim])
        if self.positive:
            values, vectors = np.linalg.eigh(blocks)
            blocks = np.einsum('pak,pk,pbk->pab', vectors, np.abs(values), vectors)
        matrix = potential.spring_hessian(n) + physics.pair_block_laplacian(i, j, blocks, n)
        free = free_dofs(atoms, dim)
        keep = np.flatnonzero(free.ravel())
        shift = 1e-6 * abs(matrix.diagonal()).max()
        lu = splu(sp.csc_matrix(matrix[keep][:, keep] + shift * sp.eye(len(keep))))
        return _FallBack(lu, keep, free, springs)


class _FallBack(Solver):
    def __init__(self, lu, keep, free, springs):
        self.lu, self.keep, self.free, self.springs = lu, keep, free, springs

    def solve(self, forces):
        dim = self.free.shape[1]
        move = np.zeros((len(self.free), 3))
        flat = move[:, :dim].reshape(-1)
        flat[self.keep] = self.lu.solve(np.asarray(forces)[:, :dim].reshape(-1)[self.keep])
        move[:, :dim] = flat.reshape(-1, dim)
        if np.vdot(move, forces) > 0:
            return move
        return self.springs.solve(forces)


class NewtonCG(SpringsModel):
    """Truncated Newton with exact products, preconditioned by the springs."""

    products = 0

    def at(self, atoms, learnt=None):
        springs = super().at(atoms, learnt)
        potential, x = atoms.calc.potential, atoms.positions.copy()
        free = free_dofs(atoms, potential.dim)
        model = self

        class _CG(Solver):
            def solve(self, forces):
                dim = free.shape[1]
                mask = np.zeros((len(free), 3), dtype=bool)
                mask[:, :dim] = free
                d = np.zeros_like(forces)
                r = np.where(mask, forces, 0.0)
                z = springs.solve(r)
                p, rz, tol = z.copy(), np.vdot(r, z), min(0.5, np.sqrt(np.linalg.norm(r)))
                for k in range(50):
                    hp = np.zeros_like(p)
                    hp[:, :dim] = potential.hvp(x, p[:, :dim])
                    hp[~mask] = 0.0
                    model.products += 1
                    curvature = np.vdot(p, hp)
                    if curvature <= 0:
                        return d if k else z
                    alpha = rz / curvature
                    d, r = d + alpha * p, r - alpha * hp
                    if np.linalg.norm(r) <= tol * np.linalg.norm(forces):
                        break
                    z = springs.solve(r)
                    rz, rz_old = np.vdot(r, z), rz
                    p = z + (rz / rz_old) * p
                return d

        return _CG()


VARIANTS = {
    'springs': lambda cutoff: (SpringsModel(), {}),
    'near signed': lambda cutoff: (NearField(cutoff, positive=False), {'memory': 20}),
    'near positive': lambda cutoff: (NearField(cutoff, positive=True), {'memory': 20}),
    'newton-cg': lambda cutoff: (NewtonCG(), {'memory': 0}),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=[f'{n}:{s}' for n, s in LARGE
                                                        if (n, s) != ('hanging_net', 100)])
    parser.add_argument('--variants', nargs='+', default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument('--cutoff', type=float, default=2.5,
                        help='near field: pairs within this many neighbour distances')
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--steps', type=int, default=3000)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    lines = [f'Measured {datetime.date.today()}, one thread, fmax {args.fmax:g} Q a, seed 0: '
             f'`python benchmarks/large_model_sweep.py {" ".join(sys.argv[1:])}`', '',
             '| scene | N | model | converged | calls | H v products | CPU s | energy |',
             '|---|---|---|---|---|---|---|---|']
    warm = build('hanging_net', 4)
    Maud(warm, logfile=None).run(fmax=1e-3)
    for scene in args.scenes:
        name, size = scene.split(':')
        for variant in args.variants:
            model, keywords = VARIANTS[variant](args.cutoff)
            atoms = build(name, int(size))
            start = cpu_seconds()
            try:
                calls, cpu, done = calls_and_cpu(
                    atoms, Maud(atoms, model=model, logfile=None, **keywords),
                    args.fmax, args.steps)
            except Exception as error:   # a variant that fails is a row too
                calls, cpu, done = '-', cpu_seconds() - start, type(error).__name__
            products = getattr(model, 'products', '')
            row = (f'| {name} {size} | {len(atoms)} | {variant} | {done} | {calls} | '
                   f'{products} | {cpu:.2f} | {atoms.get_potential_energy():.10g} |')
            print(row, flush=True)
            lines.append(row)
    if args.out:
        args.out.write_text('\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
