"""Basin hopping with Maud against BFGS on all-pairs clusters, in calculator calls.

Every pair of an all-pairs cluster is sprung, so the springs act as a parabolic trap about
the centroid, ``(Q N / 2) sum |r - rbar|^2``: a charged cluster in a trap
(``scenes.all_pairs`` in 3D, ``scenes.all_pairs2d`` in 2D). For each dimension, size and
seed, :class:`ase.optimize.basin.BasinHopping` makes ``--hops`` hops with
``optimizer=BFGS`` and with ``optimizer=Maud`` (default keywords), every local relaxation to
``--fmax``, from the same start. BasinHopping draws its random displacements and its
Metropolis acceptance from numpy's global generator (``np.random.uniform``), so seeding it
(``np.random.seed(seed)``) before each run gives every optimiser the same sequence of random
numbers: the same hops, applied to the minima each optimiser found. In 2D a
``FixCartesian`` on z keeps BasinHopping's displacements (drawn in 3D) in the plane.

Counted (``ase_maud.counting.CallRecorder``): every calculator call, line searches
included, of the whole run, and its CPU seconds (``ase_maud.counting.cpu_seconds``). Reported per
run: the number of distinct minima visited (by energy, within ``--energy-rtol``), the
lowest energy found (``Q a^2``), the calls spent, the calls until the run first found
its own lowest energy, and until it first found the lowest energy of all the runs from
that start (``best``, within ``--energy-rtol``; ``inf`` if never); local relaxations
that hit the ``--relax-steps`` cap (BasinHopping then takes the energy where they
stopped), and any error. The goal: Maud reaches
``best`` in at most half of BFGS's calls. Run with one thread::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/basin_hopping.py --out bh
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import numpy as np
from ase.constraints import FixCartesian
from ase.optimize import BFGS
from ase.optimize.basin import BasinHopping
from ase.optimize.optimize import Optimizer

from ase_maud import Maud
from ase_maud.counting import CallRecorder, cpu_seconds
from ase_maud.scenes.catalogue import build

#: The compared local optimisers, by name.
OPTIMIZERS = {'BFGS': BFGS, 'Maud': Maud}
#: The cluster scene of each dimension.
CLUSTERS = {2: 'all_pairs2d', 3: 'all_pairs'}


def capped(optimizer: type[Optimizer], steps: int) -> type[Optimizer]:
    """``optimizer`` whose ``run`` stops after ``steps`` steps (BasinHopping asks for no
    limit) and counts, in ``capped.unconverged``, the runs that stopped there."""

    class Capped(optimizer):
        unconverged = 0

        def run(self, fmax: float = 0.05, steps: int = steps) -> bool:
            converged = super().run(fmax=fmax, steps=steps)
            Capped.unconverged += not converged
            return converged

    Capped.__name__ = optimizer.__name__
    return Capped


def hop(dim: int, size: int, seed: int, name: str, hops: int, fmax: float, dr: float,
        kt: float, relax_steps: int, energy_rtol: float) -> dict:
    """One basin-hopping run; returns its row without the :func:`compare` columns and
    with ``trace``, the (calls so far, energy) of the start's minimum and of each hop's."""
    atoms = build(CLUSTERS[dim], size, seed=seed)
    if dim == 2:
        atoms.set_constraint(FixCartesian(range(len(atoms)), mask=(False, False, True)))
    optimizer = capped(OPTIMIZERS[name], relax_steps)
    trace, error = [], ''
    np.random.seed(seed)            # BasinHopping's moves and acceptance
    cpu = cpu_seconds()
    with CallRecorder(atoms.calc) as recorder:
        try:
            bh = BasinHopping(atoms, temperature=kt, optimizer=optimizer, fmax=fmax, dr=dr,
                              logfile=None, trajectory=None, optimizer_logfile=None,
                              local_minima_trajectory=None)
            trace.append((len(recorder.samples), bh.Emin))
            # BasinHopping.log(step, En, Emin) runs after every hop.
            bh.log = lambda step, en, emin: trace.append((len(recorder.samples), en))
            bh.run(hops)
        except Exception as exc:    # a failed run is a result: keep what it found
            error = f'{type(exc).__name__}: {exc}'
    cpu = cpu_seconds() - cpu
    return {'dim': dim, 'size': size, 'seed': seed, 'optimiser': name, 'hops': hops,
            'calls': len(recorder.samples), 'cpu_s': cpu,
            'lowest_energy': min((e for _, e in trace), default=math.nan),
            'distinct_minima': _distinct([e for _, e in trace], energy_rtol),
            'unconverged_relaxations': optimizer.unconverged, 'error': error,
            'trace': trace}


def _distinct(energies: list[float], rtol: float) -> int:
    """How many energies differ from each other by more than ``rtol`` (relative)."""
    levels = []
    for e in sorted(energies):
        if not levels or e > levels[-1] + rtol * abs(levels[-1]):
            levels.append(e)
    return len(levels)


def _calls_to(trace: list[tuple[int, float]], energy: float, rtol: float) -> float:
    """Calls until the trace first came within ``rtol`` (relative) of ``energy``
    (a minimum found again slightly lower is the same minimum); inf if never."""
    return next((c for c, e in trace if e <= energy + rtol * abs(energy)), math.inf)


def compare(rows: list[dict], energy_rtol: float) -> None:
    """Add ``calls_to_own_lowest``, ``best_energy``, ``calls_to_best`` and
    ``calls_to_best_x_BFGS`` to the rows of one start (in place)."""
    best = min(row['lowest_energy'] for row in rows)
    for row in rows:
        trace = row.pop('trace')
        row['calls_to_own_lowest'] = _calls_to(trace, row['lowest_energy'], energy_rtol)
        row['best_energy'] = best
        row['calls_to_best'] = _calls_to(trace, best, energy_rtol)
    bfgs = next((row['calls_to_best'] for row in rows if row['optimiser'] == 'BFGS'),
                math.nan)
    for row in rows:
        row['calls_to_best_x_BFGS'] = row['calls_to_best'] / bfgs


def markdown(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    head = ['dim', 'size', 'seed', 'optimiser', 'calls', 'CPU s', 'minima visited',
            'lowest energy',
            'best energy', 'calls to own lowest', 'calls to best', 'x BFGS',
            'capped relaxations', 'error']
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for r in rows:
        cells = [r['dim'], r['size'], r['seed'], r['optimiser'], r['calls'],
                 f"{r['cpu_s']:.2f}", r['distinct_minima'], f"{r['lowest_energy']:.8f}",
                 f"{r['best_energy']:.8f}",
                 r['calls_to_own_lowest'], r['calls_to_best'],
                 f"{r['calls_to_best_x_BFGS']:.2f}", r['unconverged_relaxations'],
                 r['error'] or '']
        lines.append('| ' + ' | '.join(map(str, cells)) + ' |')
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--dims', type=int, nargs='+', choices=CLUSTERS, default=[2, 3])
    parser.add_argument('--sizes', type=int, nargs='+', default=[13, 19, 26])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0])
    parser.add_argument('--optimizers', nargs='+', choices=OPTIMIZERS,
                        default=list(OPTIMIZERS))
    parser.add_argument('--hops', type=int, default=30)
    parser.add_argument('--fmax', type=float, default=1e-3,
                        help='fmax of every local relaxation (Q a; default: %(default)s)')
    parser.add_argument('--dr', type=float, default=0.5,
                        help="BasinHopping's largest displacement per coordinate "
                        '(a; default: %(default)s)')
    parser.add_argument('--kt', type=float, default=0.1,
                        help="BasinHopping's temperature (Q a^2; default: %(default)s)")
    parser.add_argument('--relax-steps', type=int, default=5000,
                        help='step cap of a local relaxation (default: %(default)s)')
    parser.add_argument('--energy-rtol', type=float, default=1e-6,
                        help='relative energy within which a run found the best minimum '
                        '(default: %(default)s)')
    parser.add_argument('--out', default='basin-hopping', help='output directory')
    args = parser.parse_args(argv)
    rows = []
    for dim in args.dims:
        for size in args.sizes:
            for seed in args.seeds:
                start = [hop(dim, size, seed, name, args.hops, args.fmax, args.dr,
                             args.kt, args.relax_steps, args.energy_rtol)
                         for name in args.optimizers]
                compare(start, args.energy_rtol)
                rows += start
                for r in start:
                    print(f"{dim}D {size} seed {seed} {r['optimiser']}: lowest "
                          f"{r['lowest_energy']:.8f} in {r['calls']} calls, best after "
                          f"{r['calls_to_best']}", file=sys.stderr, flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / 'basin_hopping.csv', 'w', newline='') as fd:
        writer = csv.DictWriter(fd, list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(markdown(rows), end='')
    print(f'results in {out}/basin_hopping.csv')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
