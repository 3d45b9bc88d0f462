"""Seconds to read a 224 x 224 quad grid (50,176 points) with its boundary
fixed, by ``read_net`` from OBJ and from PLY, against ``meshio.read`` alone,
and ``boundary_vertices`` of its faces; best of ``--repeat`` runs. The
figures are printed and saved (``--out``, Markdown)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/read_net_speed.py \\
        --out docs/dev/bench/read_net_speed.md

The machine may be shared with other jobs: the figures are wall-clock times
of the best run, not of an idle machine.
"""

from __future__ import annotations

import argparse
import datetime
import platform
import sys
import tempfile
import time
from pathlib import Path

import meshio
import numpy as np

from ase_maud.io.nets import read_net
from ase_maud.physics.topology import boundary_vertices

#: The goals of issue 55, seconds.
GOALS = {'read_net OBJ': 0.6, 'read_net PLY': 0.15}


def grid_mesh(n: int) -> meshio.Mesh:
    """An n x n grid of points on a gentle hump, quads between them."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing='ij')
    points = np.c_[x.ravel(), y.ravel(), 0.1 * np.sin(np.pi * x.ravel()) * y.ravel()]
    index = np.arange(n * n).reshape(n, n)
    quads = np.c_[index[:-1, :-1].ravel(), index[1:, :-1].ravel(),
                  index[1:, 1:].ravel(), index[:-1, 1:].ravel()]
    return meshio.Mesh(points, [('quad', quads)])


def best(call, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--n', type=int, default=224)
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    if args.out is not None and args.out.exists():
        parser.error(f'--out {str(args.out)!r} exists: give a new file')
    mesh = grid_mesh(args.n)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for suffix in ('obj', 'ply'):
            path = Path(folder) / f'grid.{suffix}'
            mesh.write(path)
            rows.append((f'meshio.read {suffix.upper()}',
                         best(lambda p=path: meshio.read(p), args.repeat)))
            rows.append((f'read_net {suffix.upper()}',
                         best(lambda p=path: read_net(p, fixed='boundary'), args.repeat)))
    faces = mesh.cells[0].data.tolist()
    rows.append(('boundary_vertices', best(lambda: boundary_vertices(faces), args.repeat)))
    lines = [f'# read_net on a {args.n} x {args.n} grid ({args.n ** 2} points)', '',
             f'{datetime.date.today()}, {platform.processor() or platform.machine()}, '
             f'best of {args.repeat}; the machine was shared with other jobs, so these '
             'are upper bounds.', '', '| what | seconds | goal |', '|---|---|---|']
    for name, seconds in rows:
        goal = GOALS.get(name)
        met = '' if goal is None else f'{goal} ({"met" if seconds <= goal else "NOT met"})'
        lines.append(f'| {name} | {seconds:.3f} | {met} |')
    report = '\n'.join(lines) + '\n'
    sys.stdout.write(report)
    if args.out is not None:   # saved as printed
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with open(args.out, 'x') as handle:   # an existing file is never replaced
            handle.write(report)


if __name__ == '__main__':
    main()
