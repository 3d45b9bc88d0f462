"""Inverse form finding: the force densities that make a hanging net pass
through chosen heights (ase_maud.form.inverse, docs/form_finding.md).

A 30 x 30 grid, its boundary held, self-weight on every point: the ``a = 0``
form (the force-density method) with every ``q = 1`` sags into a bowl. We
ask for a flatter, ridged form instead: given heights at 9 points. L-BFGS-B
on the adjoint gradient of the force-density solve finds ``q`` within
``[0.1, 10]`` that meet them within 1e-6 of the net's diagonal, in a few tens
of forward solves; the form is written as OBJ with its faces::

    python examples/inverse_form_finding.py [--out form.obj]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms

from ase_maud import MaudCalculator
from ase_maud.form.force_density import solve_force_density
from ase_maud.form.inverse import find_force_densities
from ase_maud.form.member_forces import describe_result, form_result
from ase_maud.io.net_writer import write_net


def hanging_grid(n: int = 30, weight: float = 0.05) -> tuple[Atoms, np.ndarray]:
    """An n x n unit grid in z = 0, boundary held, ``weight`` down on every
    point, every q = 1, with its quads (``info['faces']``); and the index
    grid (n, n)."""
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing='ij')
    index = np.arange(n * n).reshape(n, n)
    springs = np.r_[np.c_[index[:-1].ravel(), index[1:].ravel()],
                    np.c_[index[:, :-1].ravel(), index[:, 1:].ravel()]]
    held = np.flatnonzero((x.ravel() % (n - 1) == 0) | (y.ravel() % (n - 1) == 0))
    loads = np.zeros((n * n, 3))
    loads[:, 2] = -weight
    atoms = Atoms(f'H{n * n}', positions=np.c_[x.ravel(), y.ravel(), np.zeros(n * n)],
                  constraint=FixAtoms(held))
    atoms.calc = MaudCalculator(springs=springs, a=0.0, loads=loads)
    atoms.info['faces'] = np.c_[index[:-1, :-1].ravel(), index[1:, :-1].ravel(),
                                index[1:, 1:].ravel(), index[:-1, 1:].ravel()]
    return atoms, index


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', help='write the form found here (.obj, .ply, .json, ...)')
    args = parser.parse_args()
    atoms, index = hanging_grid()
    solve_force_density(atoms)
    points = index[[7, 15, 22]][:, [7, 15, 22]].ravel()
    print('q = 1 everywhere: heights at the 9 points',
          np.round(atoms.positions[points, 2], 3).tolist())
    # the targets: a ridge along x, lower towards the ends
    targets = {int(p): z for p, z in zip(points, [-2.0, -2.5, -2.0, -3.0, -3.5, -3.0,
                                                  -2.0, -2.5, -2.0], strict=True)}
    start = time.perf_counter()
    result = find_force_densities(atoms, heights=targets, bounds=(0.1, 10.0))
    seconds = time.perf_counter() - start
    print(f'met {result.met}: {result.forward_solves} forward solves in {seconds:.2f} s, '
          f'largest height error {result.height_error:.2g} of the diagonal; '
          f'q from {result.q.min():.3g} to {result.q.max():.3g}')
    print('heights now', np.round(atoms.positions[points, 2], 6).tolist())
    print(describe_result(form_result(atoms), repulsion=False))
    if args.out:
        print('written:', ', '.join(map(str, write_net(args.out, atoms))))


if __name__ == '__main__':
    main()
