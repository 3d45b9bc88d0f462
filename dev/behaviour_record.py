"""Calls and end energies of Maud with every model and target, to compare two versions.

``--suite small`` (default): for each scene of the small suite and the collective scenes,
each seed, each model (``exact``, ``springs``, ``global``, ``nodal``, ``secant``) and each
target (``minimum``; ``saddle``, order 1, from the minimum the exact model found, exact and
springs only), one run to ``--fmax`` (at most ``--steps`` steps). ``--suite large``: the
large scenes of the benchmark (``ase_maud.scenes.LARGE``), the default model, to fmax
1e-4. ``--suite saddles``: one ``search_saddles(wanted=1, mirror=False)`` from the minimum
of each of a few scenes (the attempts, their force-call equivalents, the first saddle's
energy and how many were found). Written as CSV rows
``scene, size, seed, model, target, steps, calls, energy, status``. It uses the 0.1 module
paths, which 0.2 keeps, so the same script measures an older checkout too
(``PYTHONPATH=OLD_CHECKOUT``)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python dev/behaviour_record.py --out new.csv
    PYTHONPATH=../old NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python dev/behaviour_record.py --out old.csv
    python dev/behaviour_record.py --compare old.csv new.csv
"""

from __future__ import annotations

import argparse
import csv
import math

from ase_maud import Maud
from ase_maud.analysis import classify
from ase_maud.bench.runner import CallRecorder
from ase_maud.scenes import build

#: The starts of ``--suite saddles``.
SADDLE_STARTS = [('all_pairs', 12), ('tree', 40), ('random_graph', 30), ('chain', 30),
                 ('net3d', 5)]
SCENES = [('all_pairs', 10), ('all_pairs2d', 12), ('ring', 24), ('chain', 20),
          ('tree', 24), ('wheel', 12), ('random_graph', 20), ('hanging_net', 5),
          ('molecule', 'C6H6'), ('net3d', 4)]
MODELS = ['exact', 'springs', 'global', 'nodal', 'secant']
SADDLE_MODELS = ['exact', 'springs']


def run(atoms, fmax, steps, **keywords):
    """(steps, calls, energy, status) of one Maud run on ``atoms``."""
    with CallRecorder(atoms.calc) as recorder:
        try:
            with Maud(atoms, logfile=None, **keywords) as opt:
                status = 'converged' if opt.run(fmax=fmax, steps=steps) else 'not converged'
        except Exception as error:   # recorded, so that both versions are compared
            status = type(error).__name__
    return opt.nsteps, len(recorder.samples), atoms.get_potential_energy(), status


def record(seeds, fmax, steps):
    rows = []
    for name, size in SCENES:
        for seed in seeds:
            for model in MODELS:
                atoms = build(name, size, seed=seed)
                done = run(atoms, fmax, steps, model=model)
                rows.append([name, size, seed, model, 'minimum', *done])
            minimum = build(name, size, seed=seed)
            run(minimum, 1e-8, steps, model='exact')
            if classify(minimum).verdict != 'minimum':
                continue
            for model in SADDLE_MODELS:
                start = minimum.copy()
                start.calc = type(minimum.calc)(**minimum.calc.parameters)
                start.set_constraint(minimum.constraints)
                done = run(start, fmax, steps, model=model, target='saddle')
                rows.append([name, size, seed, model, 'saddle', *done])
    return rows


def record_large(seeds, steps):
    """One default Maud run to fmax 1e-4 on each large scene and seed."""
    from ase_maud.scenes import LARGE
    return [[name, size, seed, 'auto', 'minimum',
             *run(build(name, size, seed=seed), 1e-4, steps)]
            for name, size in LARGE for seed in seeds]


def record_saddles(seeds, steps):
    """One search for one saddle from the minimum of each start and seed."""
    from ase_maud.activation import search_saddles
    rows = []
    for name, size in SADDLE_STARTS:
        for seed in seeds:
            minimum = build(name, size, seed=seed)
            run(minimum, 1e-9, steps)
            found = search_saddles(minimum, wanted=1, seed=seed, mirror=False)
            energy = (found.saddles[0].get_potential_energy() if found.saddles
                      else float('nan'))
            rows.append([name, size, seed, 'search', 'saddle', len(found.attempts),
                         found.cost, energy, f'{len(found.saddles)} found'])
    return rows


def compare(old_path, new_path):
    """Print each row whose calls or energy differ, and a summary."""
    def load(path):
        with open(path) as handle:
            return {tuple(r[:5]): r[5:] for r in csv.reader(handle)}
    old, new = load(old_path), load(new_path)
    same = 0
    for key in old:
        if key not in new:
            continue
        (_, c0, e0, st0), (_, c1, e1, st1) = old[key], new[key]
        if c0 == c1 and st0 == st1 and (math.isclose(float(e0), float(e1), rel_tol=1e-9)
                                        or math.isnan(float(e0)) and math.isnan(float(e1))):
            same += 1
        else:
            print(' '.join(key), f'calls {c0} -> {c1}, energy {e0} -> {e1}, {st0} -> {st1}')
    print(f'{same} of {len(old)} runs the same (calls, status, energy to 1e-9)')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1])
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--steps', type=int, default=2000)
    parser.add_argument('--suite', choices=['small', 'large', 'saddles'], default='small')
    parser.add_argument('--out')
    parser.add_argument('--compare', nargs=2, metavar=('OLD', 'NEW'))
    args = parser.parse_args()
    if args.compare:
        compare(*args.compare)
        return
    with open(args.out, 'x', newline='') as handle:
        rows = {'small': lambda: record(args.seeds, args.fmax, args.steps),
                'large': lambda: record_large(args.seeds, args.steps),
                'saddles': lambda: record_saddles(args.seeds, args.steps)}[args.suite]()
        csv.writer(handle).writerows(rows)


if __name__ == '__main__':
    main()
