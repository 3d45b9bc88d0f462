"""The snap-through saddle of a dome:
:func:`ase_maud.saddles.between_minima.saddle_between` from a net
with its whole rim fixed (:func:`ase_maud.scenes.saddle_scenes.rim`: ``net3d`` of
``size`` x ``size``
points, every coordinate moved by up to 0.25 a, seeded), relaxed to a dome, to its mirror
image (:func:`ase_maud.saddles.between_minima.mirrored`).

Per size and seed: the CPU and wall seconds of the two minima and of the search, the band's
calls (summed over its moving images) and steps, the refinement's calls, Hessian-vector
product vectors and Hessians, their sum (force-call equivalents), the barriers above either
minimum, the band's highest image, and the saddle classified again from a fresh calculator
(index, zero curvatures, fmax). Rows go to ``OUT/snap_through.csv`` and a table to
``OUT/snap_through.md``. Run::

    NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=2 OPENBLAS_NUM_THREADS=2 \\
        python benchmarks/snap_through.py --sizes 20 --seeds 0 1 2 --out docs/dev/bench/snap_through
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
import warnings
from pathlib import Path

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import cpu_seconds, fresh_copy
from ase_maud.saddles.between_minima import mirrored, saddle_between
from ase_maud.scenes.saddle_scenes import SADDLE_SCENES

COLUMNS = ('size', 'natoms', 'seed', 'threads', 'ends_cpu_s', 'cpu_s', 'wall_s', 'band_calls',
           'band_steps', 'saddle_calls', 'hvp_vectors', 'hessians', 'cost', 'barrier',
           'barrier_back', 'climbing', 'index', 'zero', 'fmax', 'outcome')


def one(size: int, seed: int, fmax: float) -> dict:
    """The row of one dome of ``size`` x ``size`` points and ``seed``."""
    cpu = cpu_seconds()
    first = SADDLE_SCENES['rim'](size, seed)
    if not Maud(first, logfile=None).run(fmax=1e-9, steps=5000):
        raise ValueError(f'rim {size} seed {seed} did not relax')
    second = mirrored(first, fmax=1e-9)
    ends = cpu_seconds() - cpu
    wall = time.perf_counter()
    found = saddle_between(first, second, fmax=fmax)
    wall = time.perf_counter() - wall
    row = {'size': size, 'natoms': len(first), 'seed': seed,
           'threads': os.environ.get('NUMBA_NUM_THREADS', ''), 'ends_cpu_s': round(ends, 2),
           'cpu_s': round(found.cpu_s, 2), 'wall_s': round(wall, 2),
           'band_calls': found.band_calls, 'band_steps': found.band_steps,
           'saddle_calls': found.saddle_calls, 'hvp_vectors': found.work.hvp_vectors,
           'hessians': found.work.hessians, 'cost': found.cost,
           'barrier': found.barriers[0], 'barrier_back': found.barriers[1],
           'climbing': found.climbing, 'index': '', 'zero': '', 'fmax': '',
           'outcome': found.outcome or 'saddle'}
    if found.saddle is not None:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            point = classify(fresh_copy(found.saddle))
        row.update(index=point.index, zero=point.n_zero, fmax=f'{point.fmax:.2e}')
    return row


def table(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    keys = ('natoms', 'seed', 'threads', 'cpu_s', 'wall_s', 'band_calls', 'band_steps',
            'saddle_calls', 'hvp_vectors', 'hessians', 'cost', 'barrier', 'climbing',
            'index', 'fmax')
    lines = ['| ' + ' | '.join(keys) + ' |', '|' + '---|' * len(keys)]
    for row in rows:
        lines.append('| ' + ' | '.join(f'{row[k]:.4f}' if k in ('barrier', 'climbing')
                                       else str(row[k]) for k in keys) + ' |')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[20])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--out', type=Path, default=Path('snap_through'))
    args = parser.parse_args(argv)
    rows = []
    for size in args.sizes:
        for seed in args.seeds:
            row = one(size, seed, args.fmax)
            rows.append(row)
            print(' '.join(f'{k}={row[k]}' for k in COLUMNS), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / 'snap_through.csv', 'w', newline='') as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    (args.out / 'snap_through.md').write_text(table(rows))
    print(table(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
