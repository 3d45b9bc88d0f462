"""Saddle searches from large minima: :func:`ase_maud.saddles.search.search_saddles` (whole-scene
climbs along the lowest modes, then local activations), in force-call equivalents and CPU.

Each start is a scene relaxed with Maud to fmax 1e-9 and checked to be a minimum
(:func:`ase_maud.analysis.stationary.classify`), named ``scene:size``; the scenes are
:func:`ase_maud.scenes.catalogue.build`'s and those of :mod:`ase_maud.scenes.saddle_scenes`
(``chords``: a ring with a chord
from each point to the one a third of the way round, 2D; ``corners``: a free net with its four
corners fixed; ``rim``: the net with its whole rim fixed, which buckles into a dome; ``tube``: a
tube of ``size`` rings of ``size`` points with both end rings fixed). From each start and seed
(the scene's and the search's: which points are activated) one search for one saddle
(``wanted=1``): ``--modes`` whole-scene climbs both ways, then up to ``--local`` activations, each
attempt within ``--budget`` force-call equivalents, to ``--fmax``; where those found nothing,
the path to the minimum's mirror image through the plane of its fixed points wherever the
image is another configuration (search_saddles' default; ``--mirror`` forces it on the scenes
with fixed points: the image's relaxation, the band and the refinement counted as one
attempt, with no budget but their steps). The headline is the CPU of a search in units of one
energy-and-forces call of the scene (``SaddleSearch.force_call_cpu_s``).

Counted per search: the calculator's calls, the Hessian-vector product vectors and the Hessians
(:class:`ase_maud.counting.Work`, the minimum's modes included), their sum (force-call
equivalents), CPU seconds (``ase_maud.counting.cpu_seconds``, every thread: run with one),
the attempts and
how each ended. The saddle found is classified again from a fresh calculator (index, fmax).
Rows go to ``OUT/activation.csv`` and the table to ``OUT/activation.md``. Run::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/saddle_search.py --starts chords:300 rim:19 --seeds 0 1 2 --out activation
"""

from __future__ import annotations

import argparse
import csv
import sys
import warnings
from pathlib import Path

import numpy as np

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import cpu_seconds, fresh_copy
from ase_maud.saddles.search import search_saddles
from ase_maud.scenes.catalogue import build
from ase_maud.scenes.saddle_scenes import SADDLE_SCENES

#: The scenes with fixed points to fit a plane to (the tube's two end rings too): ``--mirror``
#: gives their searches the path to the mirror image through that plane where the climbs and
#: local activations find no saddle.
MIRRORED = ('rim', 'corners', 'tube')


def minimum(scene: str, size: int, seed: int):
    """The scene relaxed to fmax 1e-9 (a ValueError if that is not a minimum) and its
    classification."""
    atoms = SADDLE_SCENES[scene](size, seed) if scene in SADDLE_SCENES else build(scene, size, seed)
    Maud(atoms, logfile=None).run(fmax=1e-9, steps=5000)
    point = classify(atoms)
    if point.verdict != 'minimum':
        raise ValueError(f'{scene} {size} seed {seed} relaxed to a {point.verdict}, not a '
                         'minimum')
    return atoms, point


def one(start: str, seed: int, args: argparse.Namespace) -> dict:
    """The row of one search from ``start`` with ``seed``."""
    scene, size = start.split(':')
    atoms, point = minimum(scene, int(size), seed)
    cpu = cpu_seconds()
    found = search_saddles(atoms, modes=args.modes, local=args.local, wanted=1,
                           budget=args.budget, fmax=args.fmax, steps=args.steps, seed=seed,
                           mirror=True if args.mirror and scene in MIRRORED else None)
    cpu = cpu_seconds() - cpu
    row = {'start': start, 'seed': seed, 'natoms': len(atoms), 'found': bool(found.saddles),
           'calls': sum(a.calls for a in found.attempts),
           'hvp_vectors': sum(a.hvp_vectors for a in found.attempts) + found.work.hvp_vectors,
           'hessians': sum(a.hessians for a in found.attempts) + found.work.hessians,
           'cost': found.cost, 'cpu_s': cpu,
           'cpu_in_force_calls': cpu / found.force_call_cpu_s,
           'force_call_cpu_s': found.force_call_cpu_s, 'attempts': len(found.attempts),
           'index': '', 'fmax': '', 'barrier': '',
           'outcomes': '; '.join(f"{a.kind} {a.where}: {a.outcome} ({a.cost})"
                                 for a in found.attempts)}
    if found.saddles:
        saddle = fresh_copy(found.saddles[0])
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            check = classify(saddle)
        row.update(index=check.index, fmax=check.fmax, barrier=(
            saddle.get_potential_energy() - atoms.get_potential_energy()))
    return row


def winning(row: dict) -> int | None:
    """The force-call equivalents of the attempt that found the row's saddle (its
    ``outcomes``: ``kind where: saddle (cost)``), or None."""
    for outcome in str(row['outcomes']).split('; '):
        if ': saddle (' in outcome:
            return int(outcome.rsplit('(', 1)[1].rstrip(')'))
    return None


def summary(rows: list[dict], fmax: float) -> str:
    """Per start and in all: searches that found a verified index-1 saddle, and the median
    force-call equivalents and CPU seconds of those (and of all searches), and of the
    attempt that found the saddle alone."""
    lines = ['| start | N | verified index 1 | median CPU in force calls (all) | '
             'median equivalents (found) | '
             'median CPU s (found) | median equivalents (all) | median CPU s (all) | '
             'median equivalents of the finding attempt |',
             '|---|---|---|---|---|---|---|---|---|']
    groups = {s: [r for r in rows if r['start'] == s]
              for s in dict.fromkeys(r['start'] for r in rows)}
    for name, mine in [*groups.items(), ('all', rows)]:
        hits = [r for r in mine if r['found'] and r['index'] == 1 and float(r['fmax']) <= fmax]

        def med(key, of):
            return f"{np.median([float(r[key]) for r in of]):.0f}" if of else '-'
        cpu = (f"{np.median([float(r['cpu_s']) for r in hits]):.2f}" if hits else '-')
        alone = [winning(r) for r in hits]
        lines.append(f"| {name} | {mine[0]['natoms'] if name != 'all' else ''} | "
                     f"{len(hits)} of {len(mine)} | {med('cpu_in_force_calls', mine)} | "
                     f"{med('cost', hits)} | {cpu} | "
                     f"{med('cost', mine)} | {np.median([float(r['cpu_s']) for r in mine]):.2f} | "
                     f"{f'{np.median(alone):.0f}' if alone else '-'} |")
    return '\n'.join(lines) + '\n'


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--starts', nargs='+', default=['chords:300', 'rim:19', 'corners:20',
                                                        'tube:20'])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    parser.add_argument('--modes', type=int, default=1)
    parser.add_argument('--local', type=int, default=8)
    parser.add_argument('--budget', type=int, default=500)
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--steps', type=int, default=1000)
    parser.add_argument('--mirror', action='store_true',
                        help='where nothing else found a saddle, the path to the mirror image '
                        f'through the plane of the fixed points (scenes {", ".join(MIRRORED)}), '
                        'even where the image is the minimum again')
    parser.add_argument('--out', type=Path, default=Path('activation'))
    parser.add_argument('--tables-from', type=Path, metavar='CSV',
                        help='write the table of the rows of a CSV this tool wrote, running '
                        'nothing')
    args = parser.parse_args(argv)
    rows = []
    if args.tables_from is not None:
        with open(args.tables_from, newline='') as fh:
            rows = [{**r, 'found': r['found'] == 'True',
                     'index': int(r['index']) if r['index'] else ''}
                    for r in csv.DictReader(fh)]
        args.starts = []
    for start in args.starts:
        for seed in args.seeds:
            try:
                row = one(start, seed, args)
            except ValueError as error:   # a start that is no minimum is left out, said
                print(f'{start:12s} {seed:3d} left out: {error}', flush=True)
                continue
            rows.append(row)
            print(f"{start:12s} {seed:3d} found {row['found']!s:5s} index {row['index']!s:2s} "
                  f"{row['calls']:5d} calls {row['hvp_vectors']:6d} HVP vectors "
                  f"{row['hessians']:4d} Hessians {row['cost']:6d} in all {row['cpu_s']:7.2f} s "
                  f"= {row['cpu_in_force_calls']:8.0f} force calls' CPU "
                  f"{row['attempts']} attempts: {row['outcomes']}", flush=True)
    if not rows:
        print('no start was a minimum: nothing written', file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / 'activation.csv', 'w', newline='') as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = summary(rows, args.fmax)
    (args.out / 'activation.md').write_text(table)
    print(table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
