"""Which ``a``, as a fraction of the mean spring length, keeps a relaxed form
within its supports, on the sample nets that ship with compas.

Each net (OBJ or COMPAS JSON in ``compas/data/samples``) is read by
``ase_maud.io.nets.read_net`` with its supports by rule (``fixed='boundary'`` for
a mesh, ``'leaves'`` for a line network) and ``a`` = fraction x its mean
spring length, and relaxed with Maud as ``ase-maud relax`` does (``--fmax``
in force units, default the command's 1e-3; ``--steps``). For every net and
fraction the table gives whether it converged, the force calls, and how far
the free points reach beyond the bounding box of the fixed ones
(``ase_maud.physics.topology.support_excursion``) as a fraction of the box's
diagonal: ``ase-maud relax`` warns above 0.1. Printed, and written with the
date and the command to ``--out``::

    pip install -e '.[bench]'
    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/a_rule.py --out docs/dev/bench/a_rule.md
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from pathlib import Path

from ase_maud import Maud
from ase_maud.counting import CallRecorder
from ase_maud.io.nets import mean_spring_length, read_compas, read_net, read_obj
from ase_maud.physics.topology import A_PER_MEAN_SPRING, support_excursion

#: The compas samples of the measurement: meshes and line networks.
SAMPLES = ['faces.obj', 'faces_big.obj', 'hypar.obj', 'quadmesh.obj', 'tubemesh.obj',
           'saddle.obj', 'grid_irregular.obj', 'lines_big.obj', 'mesh_100_faces.json',
           'tubemesh.json']
FRACTIONS = [0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0]


def sample_path(name: str) -> Path:
    import compas
    return Path(compas.get(name))


def supports_rule(path: Path) -> str:
    """'boundary' for a mesh (a file with faces), else 'leaves'."""
    net = read_obj(path) if path.suffix == '.obj' else read_compas(path)
    return 'boundary' if net.faces else 'leaves'


def relax(path: Path, rule: str, fraction: float, fmax: float, steps: int) -> dict:
    """One relaxation of ``path`` at ``a`` = ``fraction`` x mean spring length."""
    atoms = read_net(path, fixed=rule)
    mean = mean_spring_length(atoms.positions, atoms.calc.springs)
    atoms = read_net(path, fixed=rule, a=fraction * mean)
    start = time.perf_counter()
    with CallRecorder(atoms.calc) as recorder, Maud(atoms, logfile=None) as opt:
        converged = opt.run(fmax=fmax, steps=steps)
    beyond, diagonal = support_excursion(atoms)
    return {'net': path.name, 'points': len(atoms), 'rule': rule, 'fraction': fraction,
            'a': fraction * mean, 'converged': converged, 'calls': len(recorder.samples),
            'wall_s': time.perf_counter() - start, 'beyond': beyond / diagonal}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--samples', nargs='+', default=SAMPLES)
    parser.add_argument('--fractions', nargs='+', type=float, default=FRACTIONS)
    parser.add_argument('--fmax', type=float, default=1e-3)
    parser.add_argument('--steps', type=int, default=1000)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    relax(sample_path('hypar.obj'), 'boundary', 0.4, args.fmax, 50)   # kernels compiled
    rows = []
    for name in args.samples:
        path = sample_path(name)
        rule = supports_rule(path)
        for fraction in args.fractions:
            rows.append(relax(path, rule, fraction, args.fmax, args.steps))
            print(rows[-1], flush=True)
    head = ' | '.join(f'{f:g}' for f in args.fractions)
    lines = [f'Measured {datetime.date.today()}, one thread, fmax {args.fmax:g}, at most '
             f'{args.steps} steps: `python benchmarks/a_rule.py {" ".join(sys.argv[1:])}`. '
             'Each cell: how far the free points reach beyond the bounding box of the fixed '
             "ones, over the box's diagonal (ase-maud relax warns above 0.1), and the force "
             "calls (* not converged). The rule's fraction: "
             f'{A_PER_MEAN_SPRING:g} (ase_maud.io.nets.A_PER_MEAN_SPRING).', '',
             f'| net | points | supports | {head} |',
             '|---|---|---|' + '---|' * len(args.fractions)]
    for name in args.samples:
        own = [r for r in rows if r['net'] == Path(name).name]
        cells = ' | '.join(f'{r["beyond"]:.3f} ({r["calls"]}{"" if r["converged"] else "*"})'
                           for r in own)
        lines.append(f'| {own[0]["net"]} | {own[0]["points"]} | {own[0]["rule"]} | {cells} |')
    print('\n'.join(lines))
    if args.out:
        args.out.write_text('\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
