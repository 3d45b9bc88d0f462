"""A threaded Barnes-Hut tree code as the repulsion's far field: pytreegrav
(numba, parallel over targets, monopoles or quadrupoles) against the numba
direct sum and ``backend='auto'`` on the scenes of ``fmm_threads.py``.

Issue 54 asks for one E+F call of 6x10^4 points at ``tol = 1e-4`` in at most
0.3x the 2-thread direct sum's wall. The FMM3D wheel runs on one core a
process; a tree code that threads is the other way to both cores. For each
geometry, N, multipole order and opening angle ``theta``: pytreegrav's
potential and accelerations from one tree (unit masses, no softening, ``G =
1``: the repulsion's unit law with the opposite sign), the largest force
error (norm over points) relative to the largest force and the energy's
relative error against the direct sum, and the wall seconds of each, best of
``--repeats`` interleaved. The summary gives, per geometry, the fastest
setting whose force error is within ``--tol`` and its wall over the direct
sum's, beside ``auto``'s at that ``tol``. Rows go to ``OUT/tree_library.csv``
(a new directory). pytreegrav is not a dependency of ase-maud::

    pip install pytreegrav
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=2 \\
        python benchmarks/tree_library.py --out tree_library_run
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import time
from pathlib import Path

import numba
import numpy as np
from fmm_threads import GEOMETRIES, load_average, scene, timed

from ase_maud.backends import auto, direct

THETAS = (0.7, 0.5, 0.4, 0.3, 0.25, 0.2)


def tree_call(p: np.ndarray, theta: float, quadrupole: bool):
    """pytreegrav's energy sum and forces in the repulsion's units (one
    tree for both walks, built inside the call)."""
    import pytreegrav
    m = np.ones(len(p))
    tree = pytreegrav.ConstructTree(p, m, quadrupole=quadrupole)
    options = dict(tree=tree, theta=theta, parallel=True, quadrupole=quadrupole,
                   method='tree')
    potential = pytreegrav.Potential(p, m, **options)
    acceleration = pytreegrav.Accel(p, m, **options)
    return -0.5 * potential.sum(), -acceleration


def rows_of(geometry: str, n: int, thetas, repeats: int, tol: float) -> list[dict]:
    """One row per setting on ``n`` points of ``geometry``, and one for
    ``auto`` at ``tol`` and one for the direct sum."""
    p = scene(geometry, n, 0)
    (energy, forces, _), _, _ = timed(direct.evaluate, p, False)
    scale = np.linalg.norm(forces, axis=1).max()
    settings = [('numba', None, None), ('auto', None, None)] + [
        ('pytreegrav', theta, quad) for quad in (False, True) for theta in thetas]
    best = dict.fromkeys(settings, np.inf)
    errors = {}
    for _ in range(repeats):
        for setting in settings:
            what, theta, quad = setting
            if what == 'numba':
                (e, f, _), wall, _ = timed(direct.evaluate, p, False)
            elif what == 'auto':
                (e, f, _), wall, _ = timed(auto.evaluate, p, False, tol)
            else:
                (e, f), wall, _ = timed(tree_call, p, theta, quad)
            best[setting] = min(best[setting], wall)
            errors[setting] = (np.linalg.norm(f - forces, axis=1).max() / scale,
                               abs(e - energy) / abs(energy))
    return [{'geometry': geometry, 'n': n, 'what': what, 'theta': theta or '',
             'quadrupole': '' if quad is None else quad, 'force_error': errors[s][0],
             'energy_error': errors[s][1], 'wall_s': best[s],
             'x_direct': best[s] / best[settings[0]]}
            for s in settings for what, theta, quad in [s]]


def summary(rows: list[dict], tol: float) -> list[str]:
    """Per geometry and N: the fastest tree setting within ``tol`` and auto."""
    lines = []
    for key in dict.fromkeys((r['geometry'], r['n']) for r in rows):
        mine = [r for r in rows if (r['geometry'], r['n']) == key]
        auto_row = next(r for r in mine if r['what'] == 'auto')
        within = [r for r in mine if r['what'] == 'pytreegrav' and r['force_error'] <= tol]
        tree = min(within, key=lambda r: r['wall_s']) if within else None
        text = ('none within tol' if tree is None else
                f"theta {tree['theta']}, quadrupole {tree['quadrupole']}: "
                f"{tree['wall_s']:.3g} s, {tree['x_direct']:.2f}x "
                f"(error {tree['force_error']:.1e})")
        lines.append(f'- {key[0]}, N = {key[1]}: direct sum '
                     f"{next(r for r in mine if r['what'] == 'numba')['wall_s']:.3g} s; "
                     f"auto {auto_row['wall_s']:.3g} s, {auto_row['x_direct']:.2f}x; "
                     f'pytreegrav {text}')
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, required=True, help='a new directory')
    parser.add_argument('--sizes', type=int, nargs='+', default=(60000,))
    parser.add_argument('--geometries', nargs='+', default=GEOMETRIES, choices=GEOMETRIES)
    parser.add_argument('--thetas', type=float, nargs='+', default=THETAS)
    parser.add_argument('--tol', type=float, default=1e-4,
                        help='force error relative to the largest force')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    if args.out.exists():
        parser.error(f'--out {args.out} exists: give a new directory')
    if importlib.util.find_spec('pytreegrav') is None:
        parser.error('pytreegrav is not installed: pip install pytreegrav')
    args.out.mkdir(parents=True)
    load = load_average()
    rows = [row for geometry in args.geometries for n in args.sizes
            for row in rows_of(geometry, n, args.thetas, args.repeats, args.tol)]
    with open(args.out / 'tree_library.csv', 'w', newline='') as file:
        writer = csv.DictWriter(file, list(rows[0]))
        writer.writeheader()
        writer.writerows({k: f'{v:.3g}' if isinstance(v, float) else v for k, v in row.items()}
                         for row in rows)
    text = '\n'.join([f'# pytreegrav against the direct sum, tol {args.tol}',
                      f'{time.strftime("%Y-%m-%d %H:%M")}, numba threads '
                      f'{numba.get_num_threads()}, load {load} at start, '
                      f'{load_average()} at end', '']
                     + summary(rows, args.tol)) + '\n'
    (args.out / 'summary.md').write_text(text)
    print(text)


if __name__ == '__main__':
    main()
