"""Landscape completeness: the share of a minimum's connected saddles below an energy window
that the default landscape finds, against a reference from ten times as many searches.

Scenes (seeded): ``cluster``, a 2D trap cluster (``all_pairs2d`` of each of
``--cluster-sizes`` points, 13-19: every pair sprung, a parabolic trap about the centroid,
Coulomb repulsion) and ``net``, a 400-point net (``net2d`` of ``--net-sizes`` x the same
points in the plane, its boundary fixed). Each is relaxed by Maud to ``RELAX_FMAX`` and
must be a verified minimum.

From it:

- **default**: :func:`ase_maud.saddles.landscape.landscape` with its default arguments (its modes,
  local activations and seed; ``--modes`` sets the modes a round) to ``--fmax``, told the
  window (``window=``: it goes on in rounds, the next modes and points each, until its
  ``empty_rounds`` rounds in a row find no new saddle below it, then activates every free
  point no round activated: its ``sweep``); with
  ``--one-round``, not told it (one round: what the landscape did before it took a window);
- **reference**: the same function with ``--factor`` (default 10) times as many attempts
  (:class:`ase_maud.saddles.attempts.Attempt`: each climb along a mode, one way, or each local
  activation), a ``seed`` of its own (``--ref-seed``) for its local activations: half of
  the attempts local activations, at most one at each free point (an activation from a
  point is deterministic, so a second seed would repeat it), the rest climbs along the
  lowest modes both ways (at most every mode); what a scene cannot take (too few modes or
  points) is made up by the other kind, and where both are used up (every mode both ways,
  every free point: a small cluster) the reference has fewer than ``--factor`` times the
  attempts (the rows say how many). ``--net-factor`` gives the net its own factor.

A saddle **counts** when it joins the start minimum (on either side: the landscape relaxed
one side of its unstable mode back into the start, up to relabelling) and its barrier above
the start is below ``--window`` (units of ``Q a^2``). The **fraction** is the share of the
reference's counted saddles that the default landscape found too
(:func:`ase_maud.analysis.stationary.same_point`); ``default_only`` counts the default's counted
saddles that the reference missed; ``estimated`` is the landscape's own estimate of its
completeness (:attr:`ase_maud.saddles.search.SaddleSearch.coverage`, from its attempts alone,
over every saddle they reach, counted or not). Cost:
:attr:`ase_maud.saddles.landscape.Landscape.cost`, every calculator call, Hessian-vector product
vector and Hessian of the whole map (the start's classification, the attempts, the saddles'
classifications and descents), in force-call equivalents, and ``ase_maud.counting.cpu_seconds`` CPU
seconds (every thread: run with one), both also per counted saddle found. Each of the
reference's counted saddles is printed with its barrier, whether the default found it, the
reference attempt that found it first, and how many attempts of each run reached it (how
many of them local activations: a saddle few points reach needs an activation at one of
them). Rows
go to ``OUT/landscape_completeness.csv``. Run::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/landscape_completeness.py --out landscape_completeness
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

from ase import Atoms

from ase_maud import Maud
from ase_maud.analysis.stationary import classify, same_point
from ase_maud.bench.report import write_csv
from ase_maud.counting import cpu_seconds
from ase_maud.physics.dofs import free_dofs
from ase_maud.saddles.attempts import Attempt
from ase_maud.saddles.landscape import Landscape, landscape
from ase_maud.scenes.catalogue import build

#: The scenes: name -> (builder's scene, size argument).
SCENES = {'cluster': 'all_pairs2d', 'net': 'net2d'}
#: Force to which a scene is relaxed before its landscape (units of ``Q a``).
RELAX_FMAX = 1e-8

COLUMNS = ('scene', 'natoms', 'seed', 'window', 'threads', 'run', 'modes', 'local',
           'attempts', 'ratio', 'saddles', 'counted', 'reference', 'found', 'fraction',
           'estimated', 'default_only', 'minima', 'failed', 'cost', 'cost_per_saddle', 'cpu_s',
           'cpu_per_saddle')


def minimum(scene: str, size: int, seed: int) -> Atoms:
    """``scene`` of ``size`` and ``seed`` relaxed to a verified minimum."""
    atoms = build(SCENES[scene], size, seed=seed)
    if not Maud(atoms, logfile=None).run(fmax=RELAX_FMAX, steps=20000):
        raise ValueError(f'{scene} {size} seed {seed} did not relax to fmax {RELAX_FMAX:g}')
    if classify(atoms).verdict != 'minimum':
        raise ValueError(f'{scene} {size} seed {seed} did not relax to a minimum')
    return atoms


def allocation(start: Atoms, attempts: int) -> tuple[int, int]:
    """(modes, local) of a landscape making ``attempts`` attempts from ``start``: half
    local activations (at most one per free point), the rest climbs both ways along the
    lowest modes (at most every mode), each kind making up what the other cannot."""
    points = int(free_dofs(start, start.calc.potential.dim).any(axis=1).sum())
    modes_available = len(classify(start).modes)
    local = min(points, attempts // 2)
    modes = min(modes_available, math.ceil((attempts - local) / 2))
    local = min(points, max(local, attempts - 2 * modes))
    return modes, local


def counted(found: Landscape, window: float) -> list[tuple[Atoms, float, Attempt]]:
    """The saddles of ``found`` that join its start (minimum 0), their barrier above it
    below ``window``: (saddle, barrier, the attempt that found it)."""
    search = found.search
    finders = {a.saddle: a for a in search.attempts if a.outcome == 'saddle'}
    by_saddle = {id(s): finders[i] for i, s in enumerate(search.saddles)}
    energy = found.minima[0].get_potential_energy()
    return [(saddle, saddle.get_potential_energy() - energy, by_saddle[id(saddle)])
            for saddle, pair in zip(found.saddles, found.joins, strict=True)
            if 0 in pair and saddle.get_potential_energy() - energy < window]


def timed(start: Atoms, fmax: float, **kwargs) -> tuple[Landscape, float]:
    """The landscape from ``start`` with ``kwargs`` and its CPU seconds."""
    cpu = cpu_seconds()
    found = landscape(start, fmax=fmax, **kwargs)
    return found, cpu_seconds() - cpu


def compare(scene: str, size: int, seed: int, window: float, factor: int, ref_seed: int,
            fmax: float, one_round: bool, modes: int | None = None) -> list[dict]:
    """The default and reference rows of ``scene``, its missed saddles printed; ``modes``:
    the default's modes a round (None: the landscape's own default)."""
    start = minimum(scene, size, seed)
    default, default_cpu = timed(start, fmax, window=None if one_round else window,
                                 **({} if modes is None else {'modes': modes}))
    modes, local = allocation(start, factor * len(default.search.attempts))
    reference, reference_cpu = timed(start, fmax, modes=modes, local=local, seed=ref_seed)
    mine, theirs = counted(default, window), counted(reference, window)
    found = [any(same_point(s, m) for m, _, _ in mine) for s, _, _ in theirs]
    only = sum(not any(same_point(m, s) for s, _, _ in theirs) for m, _, _ in mine)
    common = {'scene': scene, 'natoms': len(start), 'seed': seed, 'window': window,
              'threads': os.environ.get('NUMBA_NUM_THREADS', '')}
    rows = []
    for run, result, cpu, kept in (('default', default, default_cpu, mine),
                                   ('reference', reference, reference_cpu, theirs)):
        arguments = result.search.attempts
        rows.append({**common, 'run': run,
                     'modes': sum(a.kind == 'mode' for a in arguments) // 2,
                     'local': sum(a.kind == 'local' for a in arguments),
                     'attempts': len(arguments),
                     'ratio': round(len(arguments) / len(default.search.attempts), 1),
                     'saddles': len(result.saddles),
                     'counted': len(kept), 'reference': len(theirs),
                     'found': sum(found) if run == 'default' else len(theirs),
                     'fraction': (round(sum(found) / len(theirs), 3)
                                  if theirs and run == 'default' else ''),
                     'estimated': ('' if result.search.coverage is None
                                   else round(result.search.coverage, 3)),
                     'default_only': only if run == 'default' else '',
                     'minima': len(result.minima), 'failed': result.failed,
                     'cost': result.cost,
                     'cost_per_saddle': round(result.cost / len(kept)) if kept else '',
                     'cpu_s': round(cpu, 2),
                     'cpu_per_saddle': round(cpu / len(kept), 3) if kept else ''})
    for (saddle, barrier, attempt), hit in sorted(zip(theirs, found, strict=True),
                                                       key=lambda item: item[0][1]):
        print(f'  {scene}: barrier {barrier:.5f} {"found" if hit else "MISSED"} '
              f'(reference: {attempt.describe()}); reached by '
              + ', '.join('{1} attempts of the {0} ({2} local)'.format(name, *reached(run, saddle))
                          for name, run in (('reference', reference), ('default', default))))
    return rows


def reached(found: Landscape, saddle: Atoms) -> tuple[int, int]:
    """The attempts of ``found``'s search that reached ``saddle`` (found it, or
    found it again), and how many of them were local activations."""
    search = found.search
    index = next((i for i, s in enumerate(search.saddles) if same_point(s, saddle)), None)
    hits = [a for a in search.attempts if index is not None and a.saddle == index]
    return len(hits), sum(a.kind == 'local' for a in hits)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scenes', nargs='+', choices=list(SCENES), default=list(SCENES))
    parser.add_argument('--cluster-sizes', type=int, nargs='+', default=[13, 15, 17, 19])
    parser.add_argument('--net-sizes', type=int, nargs='+', default=[20])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0])
    parser.add_argument('--window', type=float, default=1.0,
                        help='barrier above the start below which a saddle counts (Q a^2)')
    parser.add_argument('--factor', type=int, default=10)
    parser.add_argument('--net-factor', type=int, default=None,
                        help="the net's reference factor (default: --factor)")
    parser.add_argument('--ref-seed', type=int, default=1)
    parser.add_argument('--one-round', action='store_true',
                        help='the default landscape not told the window (one round)')
    parser.add_argument('--modes', type=int, default=None,
                        help="the default landscape's modes a round (default: the "
                        "landscape's own; more than the scene has: every mode, both ways)")
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--out', type=Path, default=Path('landscape_completeness'))
    args = parser.parse_args(argv)
    rows = []
    for scene in args.scenes:
        sizes = args.cluster_sizes if scene == 'cluster' else args.net_sizes
        factor = args.net_factor if scene == 'net' and args.net_factor else args.factor
        for size in sizes:
            for seed in args.seeds:
                for row in compare(scene, size, seed, args.window, factor, args.ref_seed,
                                   args.fmax, args.one_round, args.modes):
                    rows.append(row)
                    print(' '.join(f'{k}={row[k]}' for k in COLUMNS), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / 'landscape_completeness.csv', rows)
    return 0


if __name__ == '__main__':
    sys.exit(main())
