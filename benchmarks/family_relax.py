"""Relaxations of scenes nobody tuned for: Maud, and SciPy's L-BFGS-B for reference, on
seeded draws of the families of :mod:`ase_maud.scenes.families` (``--families``, each seed
``--seeds`` within ``--sizes`` points) and on scenes of the catalogue (``--scenes NAME:SIZE``),
to ``--fmax``; with ``--crossover N`` each calculator takes the FMM from N points (its
energies and forces then carry the FMM's declared errors, as on scenes of 10^5 points).
Maud runs once per stiffness model of ``--models`` (default ``auto``; a row's optimizer is
``Maud``, or ``Maud-near`` for ``near``, say).

Per run: the calculator calls (the start's included, as ``ase-maud bench`` counts them),
whether it converged, the end energy, the CPU seconds of the run
(``counting.cpu_seconds``, the FMM's worker processes included: run with one thread) and
its wall seconds. Printed a row a run, written to ``--out``
(a CSV; an existing file is never replaced)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/family_relax.py --families hub_net --seeds 0 1 2 \\
        --sizes 500 3000 --scenes hub_net:48 --optimizers Maud L-BFGS-B --out hubs.csv
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

from ase_maud import Maud
from ase_maud.bench.optimizers import ScipyLBFGSB
from ase_maud.counting import CallRecorder, cpu_seconds
from ase_maud.scenes.catalogue import build
from ase_maud.scenes.families import FAMILIES

OPTIMIZERS = ('Maud', 'L-BFGS-B')
FIELDS = ['scene', 'seed', 'natoms', 'optimizer', 'calls', 'converged', 'energy', 'cpu_s',
          'wall_s']


def relax(atoms, optimizer: str, fmax: float, steps: int,
          model: str = 'auto') -> tuple[int, bool, float, float]:
    """Calculator calls (the start's included), convergence, CPU and wall seconds of one
    run (Maud's with the stiffness model ``model``)."""
    cpu, wall = cpu_seconds(), time.perf_counter()
    with CallRecorder(atoms.calc) as calls:
        if optimizer == 'Maud':
            converged = Maud(atoms, model=model, logfile=None).run(fmax=fmax, steps=steps)
        else:
            converged = ScipyLBFGSB(atoms).run(fmax=fmax, steps=steps)
    return (len(calls.samples), bool(converged), cpu_seconds() - cpu,
            time.perf_counter() - wall)


def scenes(args) -> list[tuple[str, int | str, object]]:
    """(name, seed or size, builder of the Atoms) for every run asked for."""
    out = []
    for spec in args.scenes:
        name, _, size = spec.partition(':')
        size = int(size) if size else None
        out.append((name, size, lambda name=name, size=size: build(name, size)))
    for family in args.families:
        for seed in args.seeds:
            out.append((family, seed, lambda family=family, seed=seed:
                        FAMILIES[family](seed, tuple(args.sizes))))
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--families', nargs='*', default=[], choices=sorted(FAMILIES))
    parser.add_argument('--seeds', nargs='+', type=int, default=[0, 1, 2])
    parser.add_argument('--sizes', nargs=2, type=int, default=[500, 3000])
    parser.add_argument('--scenes', nargs='*', default=[],
                        help='catalogue scenes as NAME:SIZE (hub_net:48)')
    parser.add_argument('--optimizers', nargs='+', default=['Maud'], choices=OPTIMIZERS)
    parser.add_argument('--models', nargs='+', default=['auto'],
                        help="Maud's stiffness models, one run each (auto, springs, near, ...)")
    parser.add_argument('--crossover', type=int, default=None,
                        help="the calculators' crossover: the FMM from this many points")
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args(argv)
    if args.out.exists():
        sys.exit(f'{args.out} exists: not replaced')
    rows = []
    for name, seed, make in scenes(args):
        runs = [(optimizer, model) for optimizer in args.optimizers
                for model in (args.models if optimizer == 'Maud' else ['auto'])]
        for optimizer, model in runs:
            atoms = make()
            if args.crossover is not None:
                atoms.calc.set(crossover=args.crossover)
            calls, converged, cpu, wall = relax(atoms, optimizer, args.fmax, args.steps, model)
            label = optimizer if model == 'auto' else f'{optimizer}-{model}'
            row = {'scene': name, 'seed': seed, 'natoms': len(atoms), 'optimizer': label,
                   'calls': calls, 'converged': converged,
                   'energy': f'{atoms.get_potential_energy():.6f}', 'cpu_s': f'{cpu:.2f}',
                   'wall_s': f'{wall:.2f}'}
            print(' '.join(f'{row[key]}' for key in FIELDS), flush=True)
            rows.append(row)
    with args.out.open('x', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)


if __name__ == '__main__':
    main()
