"""Saddle searches: Maud's eigenvector following and signed steps against Sella, in calls and CPU.

Starts (seeded), named ``scene:size:amp``:

- ``cage:N:0``: the ``cage`` scene as built (the free point within 0.05 a of the centre),
  a saddle that shows in the free point's own nodal block;
- ``six:6:0``: the rough guess of ``examples/saddle_and_minima.py`` (six points in the plane,
  every pair sprung), next to a collective saddle: every nodal block is positive definite there;
- ``scene:N:amp``: the scene relaxed with Maud to fmax 1e-9 (a minimum, checked with
  :func:`ase_maud.analysis.stationary.classify`), then moved along its lowest Hessian mode
  so that the
  point that moves most moves ``amp`` a; ``amp`` ``up`` or ``down``: moves ``SHIFT`` = 0.1 of
  the mean nearest-neighbour distance, along the lowest mode either way, ``random``: along a
  seeded random combination of the modes. 2D scenes hold z (``keep_on_plane``: Maud never
  moves z in 2D; Sella would otherwise see z as a free, flat direction). Scenes are those of
  :func:`ase_maud.scenes.catalogue.build` and :mod:`ase_maud.scenes.saddle_scenes`:
  ``chords`` (``ring`` with a chord from each point to the one a third of the way round),
  ``corners`` (``net3d`` with its
  four corners fixed), ``rim`` (``net3d`` with its whole rim fixed: a dome) and ``tube``
  (``size`` rings of ``size`` points, both end rings fixed).

From each start, to ``--fmax`` (units of ``Q a``), at most ``--steps`` steps, seeking an
index-``--order`` point (default 1):

- ``Maud-saddle``: ``Maud(target='saddle', order=order)``, eigenvector following on the
  exact model up to 150 free degrees of freedom, minimum-mode following on the springs
  model above; ``Maud-saddle-exact``: the same with ``model='exact'`` at any size;

- ``Maud-exact``: ``Maud(target='stationary', model='exact')``, signed Newton on the analytic
  Hessian with its trust-region damping;
- ``Maud-nodal``: ``Maud(target='stationary', model='nodal')``, the specification's step;
- ``Sella``: ``Sella(order=order, internal=False)``, its Hessian estimated by its own iterative
  diagonalisation through force calls; on scenes with ``FixAtoms`` it gets ``proj_rot=False``
  (Sella projects out rotations whenever ``pbc`` is off, and on a scene with fixed points it
  then reports convergence with forces along the rotations left: fmax 0.1 on ``chain``);
- ``Sella-H``: the same with ``hessian_function`` giving the analytic Hessian
  (``MaudCalculator``'s ``hessian``), as the exact model has it.

Counted (:class:`ase_maud.counting.CallRecorder`): every ``calc.calculate`` call, Sella's
finite-difference force calls included; beside them, for Maud, what its ``work``
(:class:`ase_maud.counting.Work`) counted: the vectors it multiplied by the Hessian (each one
force-call equivalent) and the Hessians it computed (each one, though its cost is larger: it
is in the CPU seconds), the verification of the end point's index included; ``cost`` is the
sum of the three (Sella-H's analytic Hessians are not counted). CPU seconds are
``ase_maud.counting.cpu_seconds`` over the optimiser's construction and run (every
thread; run with one).
Each optimiser is run once on a small cage before the table, so imports and first compilations
are not counted. Each end point is classified (dense Hessian, a fresh calculator): index,
energy, fmax; ``same as Sella`` when its energy is within ``--energy-rtol`` (relative) of
Sella's end point and its sorted pair distances within ``--distance-atol`` (units of a). A run
that raised (Maud's StagnationError, say) is a result: its error is in the row and its end
point is classified where it stopped. Run::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/saddles_vs_sella.py --out saddles
"""

from __future__ import annotations

import argparse
import csv
import runpy
import sys
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.optimize.optimize import Optimizer

from ase_maud import Maud
from ase_maud.analysis.stationary import StationaryPoint, classify
from ase_maud.counting import CallRecorder, Work, cpu_seconds, fresh_copy
from ase_maud.saddles.landscape import same_point
from ase_maud.saddles.starts import DISPLACEMENTS, displaced_minimum, saddle_start

EXAMPLE = Path(__file__).resolve().parent.parent / 'examples' / 'saddle_and_minima.py'

#: Default starts, ``scene:size:amp`` (see the module docstring).
STARTS = ['cage:8:0', 'six:6:0', 'all_pairs2d:7:0.3', 'all_pairs2d:9:0.3',
          'all_pairs2d:16:0.3', 'all_pairs:5:0.3', 'all_pairs:6:0.3', 'all_pairs:7:0.3',
          'all_pairs:10:0.3', 'all_pairs:20:0.3', 'chain:10:0.2', 'ring:12:0.5',
          'wheel:8:0.5']


def analytic_hessian(atoms: Atoms) -> np.ndarray:
    """``MaudCalculator``'s Hessian as Sella wants it, (3N, 3N) in ``Q``: a 2D scene's
    (2N, 2N) one with zero rows and columns for z (held by FixCartesian)."""
    hessian = atoms.calc.get_property('hessian', atoms)
    n = len(atoms)
    dim = hessian.shape[0] // n
    full = np.zeros((n, 3, n, 3))
    full[:, :dim, :, :dim] = hessian.reshape(n, dim, n, dim)
    return full.reshape(3 * n, 3 * n)


def _sella(hessian: bool) -> Callable[[Atoms], Optimizer]:
    def make(atoms: Atoms) -> Optimizer:
        from sella import Sella
        fixed = any(isinstance(c, FixAtoms) for c in atoms.constraints)
        extra = {'hessian_function': analytic_hessian} if hessian else {}
        return Sella(atoms, order=ORDER[0], internal=False, logfile=None,
                     proj_rot=not fixed, **extra)
    return make


def _maud(model: str) -> Callable[[Atoms], Optimizer]:
    return lambda atoms: Maud(atoms, target='stationary', model=model, logfile=None)


def _maud_saddle(model: str) -> Callable[[Atoms], Optimizer]:
    return lambda atoms: Maud(atoms, target='saddle', order=ORDER[0], model=model,
                              logfile=None)


#: The index sought (``--order``); Sella's and Maud-saddle's ``order``.
ORDER = [1]

#: The compared saddle searches, by name.
OPTIMIZERS: dict[str, Callable[[Atoms], Optimizer]] = {
    'Maud-saddle': _maud_saddle('auto'), 'Maud-saddle-exact': _maud_saddle('exact'),
    'Maud-exact': _maud('exact'),
    'Maud-nodal': _maud('nodal'), 'Sella': _sella(hessian=False),
    'Sella-H': _sella(hessian=True)}


def make_start(scene: str, size: int, seed: int, amp: float | str) -> Atoms:
    """The start ``scene:size:amp`` (see the module docstring); ``seed`` seeds the scene
    and the random displacement (:func:`ase_maud.saddles.starts.saddle_start`; ``six``:
    the example's guess)."""
    if scene == 'six':
        return displaced_minimum(runpy.run_path(str(EXAMPLE))['guess'](), seed, amp,
                                 f'{scene} {size} seed {seed}')
    return saddle_start(scene, size, seed, amp)


def search(start: Atoms, optimiser: str, fmax: float, steps: int
           ) -> tuple[Atoms, dict, StationaryPoint]:
    """Run ``optimiser`` from a fresh copy of ``start``; return the end point, its row
    (converged, calls, Hessian-vector products, Hessians, their sum ``cost``, cpu_s,
    error) and its classification."""
    atoms = fresh_copy(start)
    converged, error = False, ''
    cpu = cpu_seconds()
    with CallRecorder(atoms.calc) as recorder:
        opt = None
        try:
            opt = OPTIMIZERS[optimiser](atoms)
            converged = bool(opt.run(fmax=fmax, steps=steps))
        except Exception as exc:  # a failed search is a result
            error = f'{type(exc).__name__}: {str(exc).splitlines()[0][:120]}'
    cpu = cpu_seconds() - cpu
    work = opt.work if isinstance(opt, Maud) else Work()
    calls = len(recorder.samples)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # a run that stopped early is not stationary
        point = classify(fresh_copy(atoms))
    row = {'optimiser': optimiser, 'converged': converged, 'calls': calls,
           'hvp_vectors': work.hvp_vectors, 'hessians': work.hessians,
           'cost': calls + work.total, 'cpu_s': cpu, 'energy': atoms.get_potential_energy(),
           'index': point.index, 'verdict': point.verdict, 'fmax': point.fmax, 'error': error}
    return atoms, row, point


def compare(start: str, seed: int, optimisers: list[str], fmax: float, steps: int,
            energy_rtol: float, distance_atol: float) -> list[dict]:
    """The rows of one start: every optimiser, and whether it ended where Sella did."""
    scene, size, amp = start.split(':')
    atoms = make_start(scene, int(size), seed, amp if amp in DISPLACEMENTS else float(amp))
    ends, rows = {}, []
    for name in optimisers:
        ends[name], row, _ = search(atoms, name, fmax, steps)
        rows.append({'start': start, 'seed': seed, 'natoms': len(atoms), **row})
    for row in rows:
        reference = ends.get('Sella')
        row['same_as_Sella'] = '' if reference is None else same_point(
            ends[row['optimiser']], reference, energy_rtol, distance_atol)
    return rows


def markdown(rows: list[dict], fmax: float) -> str:
    """The rows as a markdown table, one line per start: for each optimiser its calls,
    CPU seconds and the index of its end point, then ``=`` if that is Sella's end point
    or else its energy, and its fmax if above ``fmax`` (not converged)."""
    names = list(dict.fromkeys(r['optimiser'] for r in rows))
    head = ['start', 'seed', 'N', "Sella's end E", *names]
    lines = ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    for key in dict.fromkeys((r['start'], r['seed']) for r in rows):
        mine = {r['optimiser']: r for r in rows if (r['start'], r['seed']) == key}
        sella = mine.get('Sella')
        cells = [*key, next(iter(mine.values()))['natoms'],
                 '' if sella is None else f"{sella['energy']:.10f}"]
        for name in names:
            r = mine[name]
            cell = f"{_cost(r)}, {r['cpu_s']:.2f} s, i{r['index']}"
            cell += ' =' if r['same_as_Sella'] is True else f", E {r['energy']:.6f}"
            cell += f" (fmax {r['fmax']:.0e})" if r['fmax'] > fmax else ''
            cells.append(cell)
        lines.append('| ' + ' | '.join(map(str, cells)) + ' |')
    return '\n'.join(lines) + '\n'


def _cost(row: dict) -> str:
    """A row's force-call equivalents: ``calls+HVP vectors v+Hessians H=sum``, or
    the calls alone when it computed neither."""
    if row['cost'] == row['calls']:
        return str(row['calls'])
    return f"{row['calls']}+{row['hvp_vectors']}v+{row['hessians']}H={row['cost']}"


def found(row: dict, fmax: float) -> bool:
    """Whether the run of ``row`` ended, converged, on a point of the index sought
    (``ORDER``) with no zero curvature: a success."""
    return row['index'] == ORDER[0] and row['fmax'] <= fmax and row['verdict'] != 'degenerate'


def summary(rows: list[dict], fmax: float) -> str:
    """Per optimiser: the starts from which it ended, converged, on a point of the index
    sought (``ORDER``, no zero curvature), how many of those are Sella's end point, and
    the median calls and CPU seconds."""
    lines, order = [], ORDER[0]
    for name in dict.fromkeys(r['optimiser'] for r in rows):
        mine = [r for r in rows if r['optimiser'] == name]
        hits = [r for r in mine if found(r, fmax)]
        median = (f", median {np.median([r['calls'] for r in hits]):.0f} calls, "
                  f"{np.median([r['cost'] for r in hits]):.0f} force-call equivalents, "
                  f"{np.median([r['cpu_s'] for r in hits]):.2f} CPU s" if hits else '')
        same = sum(r['same_as_Sella'] is True for r in hits)
        lines.append(f'- {name}: an index-{order} point (fmax <= {fmax:g}) from {len(hits)} of '
                     f"{len(mine)} starts ({same} Sella's){median}{_ratios(rows, hits, fmax)}")
    return '\n'.join(lines) + '\n'


def _ratios(rows: list[dict], hits: list[dict], fmax: float) -> str:
    """The median ratios of calls and CPU seconds to Sella's over the starts where
    both found a point of the index sought (empty for Sella, or with no such start)."""
    sella = {(r['start'], r['seed']): r for r in rows
             if r['optimiser'] == 'Sella' and found(r, fmax)}
    pairs = [(r, sella[r['start'], r['seed']]) for r in hits
             if r['optimiser'] != 'Sella' and (r['start'], r['seed']) in sella]
    if not pairs:
        return ''
    calls = np.median([r['calls'] / s['calls'] for r, s in pairs])
    cost = np.median([r['cost'] / s['cost'] for r, s in pairs])
    cpu = np.median([r['cpu_s'] / s['cpu_s'] for r, s in pairs])
    return (f"; against Sella's where both do ({len(pairs)}): median ratio {calls:.2f} "
            f'calls, {cost:.2f} force-call equivalents, {cpu:.2f} CPU')


def read_rows(path: Path) -> list[dict]:
    """The rows of a CSV the tool wrote, with their types back."""
    kinds = {'seed': int, 'natoms': int, 'calls': int, 'hvp_vectors': int, 'hessians': int,
             'cost': int, 'index': int, 'cpu_s': float,
             'energy': float, 'fmax': float, 'converged': lambda v: v == 'True',
             'same_as_Sella': lambda v: {'True': True, 'False': False}.get(v, v)}
    with open(path, newline='') as fh:
        return [{k: kinds.get(k, str)(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def by_scene(rows: list[dict], fmax: float) -> str:
    """Per scene (``scene:size``) and optimiser: the starts from which it ended,
    converged, on a point of the index sought (as :func:`summary`) out of all, and
    the median calls, force-call equivalents and CPU seconds over those."""
    names = list(dict.fromkeys(r['optimiser'] for r in rows))
    lines = ['| scene | N | ' + ' | '.join(names) + ' |', '|' + '---|' * (len(names) + 2)]
    for scene in dict.fromkeys(r['start'].rsplit(':', 1)[0] for r in rows):
        mine = [r for r in rows if r['start'].rsplit(':', 1)[0] == scene]
        cells = [scene, str(mine[0]['natoms'])]
        for name in names:
            runs = [r for r in mine if r['optimiser'] == name]
            hits = [r for r in runs if found(r, fmax)]
            cells.append(f'{len(hits)} of {len(runs)}' + (
                f", {np.median([r['calls'] for r in hits]):.0f} calls, "
                f"{np.median([r['cost'] for r in hits]):.0f} equivalents, "
                f"{np.median([r['cpu_s'] for r in hits]):.2f} s" if hits else ''))
        lines.append('| ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'


def run_all(args: argparse.Namespace) -> list[dict]:
    """The rows of every start of ``args`` from every seed, by every optimiser (after
    one warm-up search each: imports, first compilations), a line printed per run."""
    for name in args.optimizers:
        search(make_start('cage', 4, 0, 0.0), name, 1e-3, 50)
    rows = []
    for start in args.starts:
        for seed in args.seeds:
            for row in compare(start, seed, args.optimizers, args.fmax, args.steps,
                               args.energy_rtol, args.distance_atol):
                rows.append(row)
                print(f"{row['start']:20s} {seed:3d} {row['optimiser']:11s} "
                      f"{row['calls']:6d} calls {row['hvp_vectors']:6d} HVP vectors "
                      f"{row['hessians']:4d} Hessians {row['cost']:6d} in all "
                      f"{row['cpu_s']:7.2f} s  E "
                      f"{row['energy']:.10f}  index {row['index']}  fmax {row['fmax']:.1e}"
                      f"  same as Sella: {row['same_as_Sella']}  {row['error']}", flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--starts', nargs='+', default=STARTS,
                        help='scene:size:amp (see the module docstring)')
    parser.add_argument('--seeds', type=int, nargs='+', default=[0])
    parser.add_argument('--optimizers', nargs='+', choices=OPTIMIZERS,
                        default=list(OPTIMIZERS))
    parser.add_argument('--order', type=int, default=1,
                        help="the index sought (Maud-saddle's and Sella's order)")
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--steps', type=int, default=1000)
    parser.add_argument('--energy-rtol', type=float, default=1e-8)
    parser.add_argument('--distance-atol', type=float, default=1e-4)
    parser.add_argument('--out', type=Path, default=Path('saddles'))
    parser.add_argument('--tables-from', type=Path, metavar='CSV',
                        help='write the tables of the rows of a CSV this tool wrote, '
                             'running nothing')
    args = parser.parse_args(argv)
    ORDER[0] = args.order
    rows = (read_rows(args.tables_from) if args.tables_from is not None
            else run_all(args))
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / 'saddles.csv', 'w', newline='') as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = (markdown(rows, args.fmax) + '\n' + summary(rows, args.fmax) + '\n'
             + by_scene(rows, args.fmax))
    (args.out / 'saddles.md').write_text(table)
    print(table)
    return 0


if __name__ == '__main__':
    sys.exit(main())
