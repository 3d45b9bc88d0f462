"""The scale benchmark: hanging nets of 10^3 to 10^6 points.

For each net (``--sides``: N = side**2 points) it measures, each in a fresh
subprocess (so that the peak resident memory is that measurement's own):

- seconds per call of every backend (``numba`` direct sum, ``fmm`` at the
  precision ``tol`` asks for, and ``auto``), energy + forces (E+F) and with
  the nodal blocks (E+F+K), wall and process CPU, and peak memory (of the
  process and its FMM workers: :class:`TreeMemory`);
- calls, wall and CPU seconds and peak memory to relax the net to ``--fmax``
  (in ``Q a``; ``--coarse-fmax`` from ``--coarse-from`` points on) with Maud
  (default model, ``backend='auto'``) for nets up to ``--relax-up-to``
  points, with SciPy's L-BFGS-B on the same calculator up to
  ``--peers-up-to`` points, and with ASE's optimisers among ``--optimizers``
  (LBFGS, FIRE) up to ``--ase-up-to`` points.

Raw rows go to ``OUT/calls.csv`` and ``OUT/relax.csv``, tables to
``OUT/summary.md``, and log-log plots to ``OUT/scale.png``::

    python benchmarks/scale.py --threads 2 --out docs/dev/bench/scale

A measurement slower than ``--budget`` seconds (estimated from the previous
size by N**2 for the direct sum) is skipped and reported as such.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

CALL_FIELDS = ('N', 'backend', 'blocks', 'wall_s', 'cpu_s', 'peak_mb', 'fmm_eps')
RELAX_FIELDS = ('N', 'optimiser', 'converged', 'calls', 'wall_s', 'cpu_s',
                'peak_mb', 'energy', 'fmax', 'fmax_asked')


class TreeMemory:
    """The peak memory of this process and its children (the FMM's worker
    processes) while it runs, in MB: their summed proportional set size
    (``Pss`` of ``/proc/<pid>/smaps_rollup``: pages a forked worker still
    shares with this process count once), sampled every ``interval`` seconds
    by a thread; at least this process's own peak resident memory (where
    ``/proc`` has no such file, that alone)."""

    def __init__(self, interval: float = 0.25):
        from ase_maud.bench.memory import tree_pss_kb  # after the job set its threads

        self.interval, self.peak_kb, self._tree_pss_kb = interval, 0, tree_pss_kb
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        me = os.getpid()
        while not self._stop.wait(self.interval):
            self.peak_kb = max(self.peak_kb, self._tree_pss_kb(me))

    def peak_mb(self) -> float:
        """Stop sampling; the peak (MB)."""
        self._stop.set()
        self._thread.join()
        own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return max(self.peak_kb, own) / 1024.0


def one_call(side: int, backend: str, blocks: bool, tol: float) -> dict:
    """Time one calculator call on a fresh net (after warm-up calls on nets
    of 16 and 576 points, which load the one-thread and the parallel kernels,
    so numba's compilation is not counted)."""
    from ase_maud.counting import cpu_seconds
    from ase_maud.scenes.catalogue import build

    kwargs = {'backend': backend, 'tol': tol}
    if backend == 'fmm':
        from ase_maud.backends.fmm import eps_for
        kwargs = {'backend': 'fmm', 'fmm_eps': eps_for(tol)}
    for warm_side in (4, 24):
        warm = build('hanging_net', warm_side)
        warm.calc.set(**kwargs)
        warm.calc.get_property('stiffness' if blocks else 'forces', warm)
    atoms = build('hanging_net', side)
    atoms.calc.set(**kwargs)
    memory = TreeMemory()
    wall, cpu = time.perf_counter(), cpu_seconds()
    atoms.calc.get_property('stiffness' if blocks else 'forces', atoms)
    wall, cpu = time.perf_counter() - wall, cpu_seconds() - cpu
    return {'N': len(atoms), 'backend': backend, 'blocks': blocks,
            'wall_s': wall, 'cpu_s': cpu, 'peak_mb': memory.peak_mb(),
            'fmm_eps': kwargs.get('fmm_eps', '')}


def one_relax(side: int, optimiser: str, fmax: float, steps: int) -> dict:
    """Relax a fresh net with ``optimiser`` (a name in the benchmark's
    OPTIMIZERS; after a warm-up on a small net) and report its calls,
    seconds and memory."""
    import numpy as np

    from ase_maud.bench.optimizers import OPTIMIZERS
    from ase_maud.bench.runner import calls_and_cpu
    from ase_maud.scenes.catalogue import build

    for warm_side in (4, 24):   # numba compiles both kernels outside the timing
        warm = build('hanging_net', warm_side)
        OPTIMIZERS[optimiser](warm).run(fmax=fmax, steps=20)
    atoms = build('hanging_net', side)
    memory = TreeMemory()
    wall = time.perf_counter()
    calls, cpu, done = calls_and_cpu(atoms, OPTIMIZERS[optimiser](atoms), fmax, steps)
    wall = time.perf_counter() - wall
    peak = memory.peak_mb()
    fmax_end = float(np.linalg.norm(atoms.get_forces(), axis=1).max())
    return {'N': len(atoms), 'optimiser': optimiser, 'converged': done,
            'calls': calls, 'wall_s': wall, 'cpu_s': cpu, 'peak_mb': peak,
            'energy': float(atoms.get_potential_energy()), 'fmax': fmax_end,
            'fmax_asked': fmax}


def _child(job: dict) -> dict | None:
    """Run one measurement in a fresh interpreter; None if it failed."""
    out = subprocess.run([sys.executable, __file__, '--job', json.dumps(job)],
                         capture_output=True, text=True)
    if out.returncode:
        print(f'  failed: {job}: {out.stderr.strip().splitlines()[-1:]}',
              file=sys.stderr)
        return None
    return json.loads(out.stdout.strip().splitlines()[-1])


def _write_csv(path: Path, fields, rows) -> None:
    with open(path, 'w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)


def _plot(calls: list[dict], relax: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from ase_maud.form.pictures import save_png

    fig, (left, middle, right) = plt.subplots(1, 3, figsize=(13, 4))
    for backend in sorted({r['backend'] for r in calls}):
        for blocks, style in ((False, '-o'), (True, '--s')):
            rows = [r for r in calls if r['backend'] == backend
                    and r['blocks'] == blocks]
            if rows:
                left.loglog([r['N'] for r in rows], [r['wall_s'] for r in rows],
                            style, label=f'{backend} {"E+F+K" if blocks else "E+F"}')
    left.set(xlabel='points N', ylabel='seconds per call (wall)',
             title='one calculator call')
    for optimiser in sorted({r['optimiser'] for r in relax}):
        rows = [r for r in relax if r['optimiser'] == optimiser and r['converged']]
        if rows:
            middle.loglog([r['N'] for r in rows], [r['calls'] for r in rows], '-o',
                          label=optimiser)
            right.loglog([r['N'] for r in rows], [r['cpu_s'] for r in rows], '-o',
                         label=optimiser)
    middle.set(xlabel='points N', ylabel='calculator calls', title='calls to fmax')
    right.set(xlabel='points N', ylabel='CPU seconds', title='CPU to fmax')
    for ax in (left, middle, right):
        ax.legend(fontsize=7)
        ax.grid(True, which='both', alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def _summary(calls, relax, args) -> str:
    lines = [f'Measured {datetime.date.today()}, {args.threads} thread(s) per pool, '
             f'`python benchmarks/scale.py {" ".join(sys.argv[1:])}`; hanging '
             f'nets (scenes.hanging_net), tol {args.tol} for the per-call rows.', '',
             '| N | backend | E+F s | E+F CPU s | E+F+K s | E+F+K CPU s | peak MB |',
             '|---|---|---|---|---|---|---|']
    keys = sorted({(r['N'], r['backend']) for r in calls})
    for n, backend in keys:
        ef = next((r for r in calls if (r['N'], r['backend'], r['blocks'])
                   == (n, backend, False)), None)
        efk = next((r for r in calls if (r['N'], r['backend'], r['blocks'])
                    == (n, backend, True)), None)

        def cell(row, key):
            return '-' if row is None else f'{row[key]:.3g}'
        peak = max((r['peak_mb'] for r in (ef, efk) if r), default=float('nan'))
        lines.append(f'| {n} | {backend} | {cell(ef, "wall_s")} | {cell(ef, "cpu_s")} '
                     f'| {cell(efk, "wall_s")} | {cell(efk, "cpu_s")} | {peak:.0f} |')
    lines += ['', 'Relaxation, backend auto:', '',
              '| N | fmax (Q a) | optimiser | converged | calls | wall s | CPU s | peak MB '
              '| energy |', '|---|---|---|---|---|---|---|---|---|']
    for r in relax:
        lines.append(f'| {r["N"]} | {r["fmax_asked"]:g} | {r["optimiser"]} | {r["converged"]} '
                     f'| {r["calls"]} | {r["wall_s"]:.1f} | {r["cpu_s"]:.1f} '
                     f'| {r["peak_mb"]:.0f} | {r["energy"]:.10g} |')
    return '\n'.join(lines) + '\n'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sides', type=int, nargs='+', default=[32, 100, 316, 1000],
                        help='net sides: N = side**2 points')
    parser.add_argument('--backends', nargs='+', default=['numba', 'fmm', 'auto'])
    parser.add_argument('--tol', type=float, default=1e-4,
                        help='force tolerance of the per-call rows (relative)')
    parser.add_argument('--optimizers', nargs='+', default=['Maud', 'L-BFGS-B'])
    parser.add_argument('--relax-up-to', type=int, default=10**4,
                        help='relax nets of at most this many points with Maud')
    parser.add_argument('--peers-up-to', type=int, default=10**4,
                        help='... and with L-BFGS-B')
    parser.add_argument('--ase-up-to', type=int, default=10**4,
                        help="... and with ASE's optimisers")
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--coarse-from', type=int, default=10**6,
                        help='nets of at least this many points relax to --coarse-fmax')
    parser.add_argument('--coarse-fmax', type=float, default=1e-3)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--budget', type=float, default=600.0,
                        help='skip a direct-sum call estimated to take longer (s)')
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--out', type=Path, default=Path('scale'))
    parser.add_argument('--job', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.job:
        job = json.loads(args.job)
        kind = job.pop('kind')
        print(json.dumps(one_call(**job) if kind == 'call' else one_relax(**job)))
        return
    for name in ('OMP_NUM_THREADS', 'NUMBA_NUM_THREADS', 'OPENBLAS_NUM_THREADS',
                 'MKL_NUM_THREADS'):
        os.environ[name] = str(args.threads)
    args.out.mkdir(parents=True, exist_ok=True)
    calls, relax = [], []
    for backend in args.backends:
        last = None   # (N, seconds) of the previous direct-sum call
        for side in args.sides:
            n = side * side
            if (backend == 'numba' and last is not None
                    and last[1] * (n / last[0]) ** 2 > args.budget):
                print(f'skip {backend} N={n}: estimated '
                      f'{last[1] * (n / last[0]) ** 2:.0f} s per call', flush=True)
                continue
            for blocks in (False, True):
                row = _child({'kind': 'call', 'side': side, 'backend': backend,
                              'blocks': blocks, 'tol': args.tol})
                if row:
                    calls.append(row)
                    print(row, flush=True)
                    last = (n, row['wall_s'])
    for side in args.sides:
        n = side * side
        fmax = args.coarse_fmax if n >= args.coarse_from else args.fmax
        for optimiser in args.optimizers:
            limit = {'Maud': args.relax_up_to, 'L-BFGS-B': args.peers_up_to}.get(
                optimiser, args.ase_up_to)
            if n > limit:
                continue
            row = _child({'kind': 'relax', 'side': side, 'optimiser': optimiser,
                          'fmax': fmax, 'steps': args.steps})
            if row:
                relax.append(row)
                print(row, flush=True)
    _write_csv(args.out / 'calls.csv', CALL_FIELDS, calls)
    _write_csv(args.out / 'relax.csv', RELAX_FIELDS, relax)
    (args.out / 'summary.md').write_text(_summary(calls, relax, args))
    _plot(calls, relax, args.out / 'scale.png')
    print(f'results in {args.out}/')


if __name__ == '__main__':
    main()
