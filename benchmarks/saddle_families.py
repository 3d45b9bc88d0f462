"""The saddle search on scenes nobody tuned for: ``search_saddles(minimum, wanted=1)`` as a
user calls it, on scenes drawn from the seeded families of :mod:`ase_maud.scenes.families`
(nets on random supports under a load, domes held on a saddle-shaped rim, chord rings, kNN
clusters, trees; random sizes within ``--sizes``).

For each family and seed: the scene relaxed with Maud to fmax 1e-8 (a start that is not then
a minimum, or whose relaxation stops with an error, is left out, and said so), one
energy-and-forces call timed (the unit), the default search for one saddle (its seed the
scene's), and the saddle it returns verified by a fresh
calculator and ``classify`` (index 1 and forces below 1e-6). Counted per search: calls,
Hessian-vector product vectors, Hessians, CPU seconds (``counting.cpu_seconds``: run with
one thread), wall seconds and numba's threads, and the headline, CPU in units of one force
call of the scene; the process's peak resident memory after the search. Printed a row a
search, then a table per family; written to ``--out`` (``rows.csv``, ``summary.md``; an
existing file is never replaced)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/saddle_families.py --seeds 0 1 --sizes 300 600 --out saddle-families
"""

from __future__ import annotations

import argparse
import csv
import resource
import sys
import time
import warnings
from pathlib import Path

import numba
import numpy as np

from ase_maud import Maud, MaudError, classify, search_saddles
from ase_maud.counting import cpu_seconds, fresh_copy
from ase_maud.scenes.families import FAMILIES

#: A saddle counts as found if its forces are below this (``Q a``).
VERIFY_FMAX = 1e-6


def one(family: str, seed: int, sizes: tuple[int, int]) -> dict | None:
    """The row of the search on ``family``'s scene of ``seed``, or None if its
    relaxation is no minimum."""
    atoms = FAMILIES[family](seed, sizes)
    try:
        Maud(atoms, logfile=None).run(fmax=1e-8, steps=5000)
    except MaudError as error:   # no minimum to start from: said, left out
        print(f'{family:12s} {seed:3d} left out: its relaxation stopped: '
              f'{str(error).splitlines()[0][:160]}', flush=True)
        return None
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        point = classify(atoms)
    if point.verdict != 'minimum':
        print(f'{family:12s} {seed:3d} left out: relaxed to a {point.verdict}', flush=True)
        return None
    cpu, wall = cpu_seconds(), time.perf_counter()
    found = search_saddles(atoms, wanted=1, seed=seed)
    cpu, wall = cpu_seconds() - cpu, time.perf_counter() - wall
    row = {'family': family, 'seed': seed, 'natoms': len(atoms),
           'dim': atoms.calc.parameters['dim'], 'verified': False, 'index': '', 'fmax': '',
           'barrier': '', 'found_by': '', 'calls': sum(a.calls for a in found.attempts),
           'hvp_vectors': sum(a.hvp_vectors for a in found.attempts) + found.work.hvp_vectors,
           'hessians': sum(a.hessians for a in found.attempts) + found.work.hessians,
           'cpu_s': round(cpu, 3), 'wall_s': round(wall, 3),
           'threads': numba.get_num_threads(), 'force_call_cpu_s': found.force_call_cpu_s,
           'cpu_in_force_calls': round(cpu / found.force_call_cpu_s),
           'peak_rss_mb': round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
           'attempts': len(found.attempts)}
    if found.saddles:
        saddle = fresh_copy(found.saddles[0])
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            check = classify(saddle)
        row.update(verified=bool(check.index == 1 and check.fmax <= VERIFY_FMAX),
                   index=check.index, fmax=f'{check.fmax:.1e}',
                   barrier=saddle.get_potential_energy() - atoms.get_potential_energy(),
                   found_by=found.found_by[0].kind)
    return row


def summary(rows: list[dict]) -> str:
    """A markdown table: per family and in all, the searches that ended on a
    verified index-1 saddle and the median and worst CPU in force calls."""
    lines = ['| family | points | verified index 1 | median CPU in force calls | worst | '
             'median CPU s |', '|---|---|---|---|---|---|']
    groups = {f: [r for r in rows if r['family'] == f] for f in dict.fromkeys(
        r['family'] for r in rows)}
    for name, mine in [*groups.items(), ('all', rows)]:
        units = [float(r['cpu_in_force_calls']) for r in mine]
        sizes = [int(r['natoms']) for r in mine]
        lines.append(f"| {name} | {min(sizes)}-{max(sizes)} | "
                     f"{sum(bool(r['verified']) for r in mine)} of {len(mine)} | "
                     f"{np.median(units):.0f} | {max(units):.0f} | "
                     f"{np.median([float(r['cpu_s']) for r in mine]):.1f} |")
    return '\n'.join(lines) + '\n'


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--families', nargs='+', choices=list(FAMILIES), default=list(FAMILIES))
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1])
    parser.add_argument('--sizes', type=int, nargs=2, default=[300, 3000],
                        metavar=('LOW', 'HIGH'))
    parser.add_argument('--out', type=Path, default=Path('saddle-families'))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name in ('rows.csv', 'summary.md'):
        if (args.out / name).exists():
            parser.error(f'--out {str(args.out)!r} holds {name} already: give a new folder')
    rows = []
    for family in args.families:
        for seed in args.seeds:
            row = one(family, seed, tuple(args.sizes))
            if row is None:
                continue
            rows.append(row)
            print(f"{family:12s} {seed:3d} N {row['natoms']:5d} verified {row['verified']!s:5s} "
                  f"{row['calls']:6d} calls {row['hvp_vectors']:6d} HVP {row['hessians']:4d} "
                  f"Hessians {row['cpu_s']:8.1f} CPU s = {row['cpu_in_force_calls']:8d} force "
                  f"calls' CPU, {row['wall_s']:.1f} s wall on {row['threads']} threads, "
                  f"peak {row['peak_rss_mb']} MB, by {row['found_by'] or '-'}",
                  flush=True)
    if not rows:
        print('no scene relaxed to a minimum: nothing written', file=sys.stderr)
        return 1
    with open(args.out / 'rows.csv', 'x', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = summary(rows)
    (args.out / 'summary.md').open('x').write(table)
    print(table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
