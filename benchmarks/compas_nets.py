"""Maud against SciPy's L-BFGS-B on the sample nets that ship with compas.

Each mesh (OBJ or COMPAS JSON in ``compas/data/samples``) is read by
``ase_maud.io.nets.read_net``; compas's own ``Mesh`` reads it again (its vertex
and face tables, for the 1.x JSON files) only to find its boundary
(``unify_cycles``, then ``vertices_on_boundary``), whose points are fixed;
``a`` is 0.4 times the mean edge length and ``Q`` is 1. Both optimisers
relax a fresh copy to ``--fmax`` (in ``Q a``) on the same calculator
(``backend='auto'``, default ``tol``), after a warm-up run of each on a
small net; calls, CPU seconds, convergence and the energy reached are
printed as a markdown table and written with the raw rows (CSV) to
``--out``::

    pip install -e '.[bench]'
    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/compas_nets.py --out docs/dev/bench/compas
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.counting import fresh_copy
from ase_maud.io.nets import read_net
from ase_maud.scenes.catalogue import build

#: The compas sample meshes (the Rhino curve files are line networks,
#: which have leaves but no boundary: benchmarks/a_rule.py relaxes those).
SAMPLES = ['faces.obj', 'faces_big.obj', 'hypar.obj', 'quadmesh.obj', 'quadmesh_planar.obj',
           'tubemesh.obj', 'tubemesh.json', 'mesh.obj', 'mesh_100_faces.json',
           'mesh_110_faces.json']
FIELDS = ('net', 'points', 'springs', 'fixed', 'a', 'optimiser', 'converged', 'calls',
          'cpu_s', 'energy')


def sample_dir() -> Path:
    import compas
    return Path(compas.__file__).parent / 'data' / 'samples'


def compas_mesh(path: Path):
    """compas's Mesh of an OBJ file, or of a COMPAS 1.x mesh JSON (its
    ``vertex`` and ``face`` tables; compas 2 reads only its own layout)."""
    from compas.datastructures import Mesh
    if path.suffix == '.obj':
        return Mesh.from_obj(str(path))
    data = json.loads(path.read_text())
    keys = {key: k for k, key in enumerate(data['vertex'])}
    vertices = [[v['x'], v['y'], v['z']] for v in data['vertex'].values()]
    faces = [[keys[key] for key in face] for face in data['face'].values()]
    return Mesh.from_vertices_and_faces(vertices, faces)


def boundary(path: Path, positions: np.ndarray) -> np.ndarray:
    """Indices (into ``positions``) of the boundary points compas finds."""
    mesh = compas_mesh(path)
    mesh.unify_cycles()
    keys = sorted(set(mesh.vertices_on_boundary()))
    if not keys:
        return np.zeros(0, dtype=int)
    points = np.array([mesh.vertex_coordinates(key) for key in keys])
    distance, index = cKDTree(positions).query(points)
    assert distance.max() <= 1e-9 * np.ptp(positions), path
    return np.unique(index)


def net(path: Path):
    """The net of ``path`` with its boundary fixed and a = 0.4 mean edge."""
    atoms = read_net(path)
    i, j = atoms.calc.springs.T
    a = 0.4 * float(np.linalg.norm(atoms.positions[i] - atoms.positions[j], axis=1).mean())
    fixed = boundary(path, atoms.positions)
    atoms = read_net(path, fixed=fixed.tolist(), a=a)
    return atoms, a, len(fixed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--samples', nargs='+', default=SAMPLES)
    parser.add_argument('--optimizers', nargs='+', default=['Maud', 'L-BFGS-B'],
                        choices=OPTIMIZERS)
    parser.add_argument('--fmax', type=float, default=1e-4, help='in units of Q a')
    parser.add_argument('--steps', type=int, default=20000)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    warm = build('hanging_net', 4)
    for optimiser in args.optimizers:   # kernels compiled or loaded outside the timing
        OPTIMIZERS[optimiser](fresh_copy(warm)).run(fmax=1e-3, steps=100)
    rows = []
    for sample in args.samples:
        start, a, fixed = net(sample_dir() / sample)
        for optimiser in args.optimizers:
            atoms = fresh_copy(start)
            calls, cpu, done = calls_and_cpu(atoms, OPTIMIZERS[optimiser](atoms),
                                             args.fmax * a, args.steps)
            rows.append({'net': sample, 'points': len(atoms),
                         'springs': len(atoms.calc.springs), 'fixed': fixed, 'a': a,
                         'optimiser': optimiser, 'converged': done, 'calls': calls,
                         'cpu_s': cpu, 'energy': atoms.get_potential_energy()})
            print(rows[-1], flush=True)
    lines = [f'Measured {datetime.date.today()}, one thread, fmax {args.fmax:g} Q a, '
             f'`python benchmarks/compas_nets.py {" ".join(sys.argv[1:])}`', '',
             '| net | points | fixed | optimiser | converged | calls | CPU s | '
             'calls / L-BFGS-B | CPU / L-BFGS-B | energy |',
             '|---|---|---|---|---|---|---|---|---|---|']
    for row in rows:
        peer = next(r for r in rows if r['net'] == row['net']
                    and r['optimiser'] == args.optimizers[-1])
        lines.append(f'| {row["net"]} | {row["points"]} | {row["fixed"]} | '
                     f'{row["optimiser"]} | {row["converged"]} | {row["calls"]} | '
                     f'{row["cpu_s"]:.2f} | {row["calls"] / peer["calls"]:.2f} | '
                     f'{row["cpu_s"] / peer["cpu_s"]:.2f} | {row["energy"]:.10g} |')
    print('\n'.join(lines))
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'summary.md').write_text('\n'.join(lines) + '\n')
        with open(args.out / 'runs.csv', 'w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=FIELDS)
            writer.writeheader()
            writer.writerows(rows)


if __name__ == '__main__':
    main()
