"""Maud's stiffness models against SciPy's L-BFGS-B on the scenes where the
repulsion, not the springs, sets the shape: free neighbour graphs, clusters,
the dense compas meshes (benchmarks/compas_nets.py's nets, boundary fixed) and the
hub net. Calls (Hessian-vector products counted as one call each, beside),
CPU seconds and the energy reached, to ``--fmax`` (in ``Q a``), one thread::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/repulsion_models.py --out docs/dev/bench/repulsion

A scene is ``name:size[:seed]`` (:func:`ase_maud.scenes.catalogue.build`, seed 0 by default) or
``compas:<sample>`` (a compas sample mesh); a variant is ``L-BFGS-B``, a
``model=`` name of :class:`ase_maud.Maud` (``near``: the package's
near-field model, :mod:`ase_maud.optimize.models.near`), ``near-all``: that model with
the repulsion block of every sprung pair (``per_point=None``, the
prototype's pairs), or ``near-lu`` / ``near-lu-<k>``: the prototype
:class:`NearFieldModel` below, the same ``P`` less the springs model's shifts,
factorised at every step or kept for ``k`` steps. The factorised prototype
measured no CPU win over the springs model (docs/dev/benchmarks.md), so it lives
here, not in the package. ``H v`` counts Hessian-vector products (each
about a force call, none here); ``P v`` the near-field model's sparse
products with its ``P`` (``work.near_products``, O(pairs) each), which the
CPU seconds hold but the calls do not.
"""

from __future__ import annotations

import argparse
import datetime
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from ase import Atoms  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

from ase_maud import Maud
from ase_maud.bench.optimizers import OPTIMIZERS  # noqa: E402
from ase_maud.bench.report import write_csv  # noqa: E402
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.counting import fresh_copy  # noqa: E402
from ase_maud.optimize.models.base import DofSolver, Solver
from ase_maud.optimize.models.near import NearModel, near_pairs  # noqa: E402
from ase_maud.optimize.models.springs import SpringsModel, _floating  # noqa: E402
from ase_maud.physics import pair_law as physics  # noqa: E402
from ase_maud.physics.dofs import free_dofs, rigid_body_modes  # noqa: E402
from ase_maud.scenes.catalogue import build  # noqa: E402

#: The most steps the near-field model waits before it tries ``P`` again.
NEAR_RETRY_MAX = 4


class NearFieldModel(SpringsModel):
    """The springs' Hessian plus the repulsion's pair blocks, signed as they
    are, of the sprung pairs and of the pairs nearer than ``cutoff`` times
    the median nearest-neighbour distance: ``P = Q (L (x) I_dim) + sum_p
    (e_i - e_j)(e_i - e_j)^T (x) Q B(r_i - r_j)``
    (:func:`ase_maud.physics.pair_law.repulsion_block`):
    the Hessian without the far field's couplings, one sparse (dim N, dim N)
    matrix factorised by SuperLU. Near a minimum it holds what the springs
    model misses where the repulsion dominates: a spring under tension
    across its repulsion is soft sideways (the blocks' ``-I / L**3``), which
    ``Q L`` takes as stiff. Far from one ``P`` is indefinite; the factor's
    pivots tell (no pivoting across the diagonal, so their signs are
    ``P``'s inertia) and the springs model steps instead, trying ``P`` again
    after 1, 2, 4 ... (at most :data:`NEAR_RETRY_MAX`) steps. A factor is
    kept for ``reuse`` steps. Points of a spring component that holds no
    fixed point get ``floor`` times the largest diagonal entry (their
    translations), and the move is projected off the rigid motions (``P``,
    short of the far field, is not invariant under rotations). Only
    ``target='minimum'`` uses ``P``; the step rule is the springs model's."""

    name = 'near-lu'

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 cutoff: float = 1.5, reuse: int = 1):
        super().__init__(target, floor)
        self.cutoff, self.reuse = float(cutoff), int(reuse)
        self._wait, self._waited = 0, 0
        self._near_kept: tuple[Solver, Solver, int] | None = None
        #: Factorisations tried, and those found positive definite.
        self.tried = self.definite = 0

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        springs = super().at(atoms, learnt)
        if self.target != 'minimum':
            return springs
        kept = self._near_kept
        if kept is not None and kept[1] is springs and kept[2] < self.reuse:
            self._near_kept = kept[0], springs, kept[2] + 1
            return kept[0]
        self._near_kept = None
        if self._waited < self._wait:
            self._waited += 1
            return springs
        near = self.factor(atoms)
        if near is None:
            self._wait, self._waited = min(NEAR_RETRY_MAX, max(1, 2 * self._wait)), 0
            return springs
        self._wait = self._waited = 0
        self._near_kept = near, springs, 1
        return near

    def matrix(self, atoms: Atoms) -> sp.csc_matrix:
        """``P`` at ``atoms``' positions on the free degrees of freedom (in the
        order of :func:`free_dofs`' mask, point by point), force per length."""
        potential = atoms.calc.potential
        n, dim = len(atoms), potential.dim
        x = potential.reduced(atoms.positions)[:, :dim]
        i, j = near_pairs(x, potential.springs, self.cutoff)
        blocks = potential.Q * physics.repulsion_block(x[i] - x[j])
        matrix = potential.spring_hessian(n) + physics.pair_block_laplacian(i, j, blocks, n)
        free = free_dofs(atoms, dim)
        keep = np.flatnonzero(free.ravel())
        largest = np.abs(matrix.diagonal()).max(initial=0.0)
        floating = np.column_stack([_floating(potential.springs, ~column) for column in free.T])
        return sp.csc_matrix(matrix[keep][:, keep]
                             + sp.diags(self.floor * largest * floating.ravel()[keep]))

    def factor(self, atoms: Atoms) -> Solver | None:
        """``P`` factorised at ``atoms``' positions, None if it is not
        positive definite."""
        self.tried += 1
        lu = splu(self.matrix(atoms), permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                  options={'SymmetricMode': True})
        if not (np.array_equal(lu.perm_r, lu.perm_c) and (lu.U.diagonal() > 0).all()):
            return None
        self.definite += 1
        free = free_dofs(atoms, atoms.calc.potential.dim)
        return NearSolver(lu.solve, free, rigid_body_modes(atoms.positions, free, free.shape[1]))


class NearSolver(DofSolver):
    """The free part of the near-field ``P`` inverted by its factor, the
    move projected off the ``rigid`` motions (orthonormal columns on the free
    degrees of freedom)."""

    def __init__(self, inverse: Any, free: np.ndarray, rigid: np.ndarray):
        super().__init__(free)
        self.inverse, self.rigid = inverse, rigid

    def _solve(self, rhs):
        move = self.inverse(rhs)
        return move - self.rigid @ (self.rigid.T @ move)


SCENES = ['neighbour_graph:1000', 'neighbour_graph:2000', 'all_pairs:300',
          'compas:mesh_100_faces.json', 'compas:mesh_110_faces.json',
          'compas:faces_big.obj', 'hub_net:48']
VARIANTS = ['L-BFGS-B', 'springs', 'near', 'near-all', 'global', 'nodal', 'near-lu',
            'near-lu-10']


def scene(spec: str):
    """The start of ``spec`` and its unit of force ``Q a`` (``a`` of a compas net)."""
    name, size, *seed = spec.split(':')
    if name == 'compas':
        from compas_nets import net, sample_dir
        atoms, a, _ = net(sample_dir() / size)
        return atoms, a
    return build(name, int(size), seed=int(seed[0]) if seed else 0), 1.0


def run(start, unit: float, variant: str, fmax: float, steps: int) -> dict:
    atoms = fresh_copy(start)
    hvp = pv = 0
    if variant in OPTIMIZERS and variant != 'Maud':
        optimiser = OPTIMIZERS[variant](atoms)
    elif variant == 'near-all':
        optimiser = Maud(atoms, model=NearModel(per_point=None), logfile=None)
    elif variant.startswith('near-lu'):
        reuse = int(variant.removeprefix('near-lu').lstrip('-') or 1)
        optimiser = Maud(atoms, model=NearFieldModel(reuse=reuse), logfile=None)
    else:
        optimiser = Maud(atoms, model=variant, logfile=None)
    calls, cpu, done = calls_and_cpu(atoms, optimiser, fmax * unit, steps)
    if isinstance(optimiser, Maud):
        hvp, pv = optimiser.model.work.total, optimiser.model.work.near_products
    return {'points': len(atoms), 'variant': variant, 'converged': done, 'calls': calls,
            'hvp': hvp, 'pv': pv, 'cpu_s': round(cpu, 3), 'energy': atoms.get_potential_energy()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=SCENES)
    parser.add_argument('--variants', nargs='+', default=VARIANTS)
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    warm = build('hanging_net', 4)
    for variant in args.variants:   # kernels compiled or loaded outside the timing
        run(warm, 1.0, variant, 1e-3, 100)
    rows = []
    for spec in args.scenes:
        start, unit = scene(spec)
        for variant in args.variants:
            rows.append({'scene': spec, **run(start, unit, variant, args.fmax, args.steps)})
            print(rows[-1], flush=True)
    lines = [f'Measured {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, one thread, '
             f'fmax {args.fmax:g} Q a: `python benchmarks/repulsion_models.py '
             f'{" ".join(sys.argv[1:])}`', '',
             '| scene | N | variant | converged | calls + H v | P v | CPU s | calls / L-BFGS-B '
             '| CPU / L-BFGS-B | energy |', '|---|---|---|---|---|---|---|---|---|---|']
    for row in rows:
        peer = next((r for r in rows if r['scene'] == row['scene']
                     and r['variant'] == 'L-BFGS-B'), row)
        total = row['calls'] + row['hvp']
        hvp = f' + {row["hvp"]}' if row['hvp'] else ''
        lines.append(f'| {row["scene"]} | {row["points"]} | {row["variant"]} | '
                     f'{row["converged"]} | {row["calls"]}{hvp} | {row["pv"]} | '
                     f'{row["cpu_s"]:.2f} | '
                     f'{total / peer["calls"]:.2f} | {row["cpu_s"] / peer["cpu_s"]:.2f} | '
                     f'{row["energy"]:.10g} |')
    print('\n'.join(lines))
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'summary.md').write_text('\n'.join(lines) + '\n')
        write_csv(args.out / 'runs.csv', rows)


if __name__ == '__main__':
    main()
