"""The FMM on one core and on two: what ``fmm_eps`` FMM3D needs for a
promised force error, and whether splitting the targets across two
processes beats one process in wall time.

Errors (``errors.csv``): for each geometry, N and seed, fmm3dpy's ``lfmm3d``
called directly at each library ``eps`` (energy + forces, and with the
Hessian), against the exact numba direct sum: the largest force error (norm
over points) relative to the largest force, the energy's relative error and
the blocks' largest error relative to their largest entry, with CPU and
wall seconds of the call. Geometries: random points at unit density in a
cube (``cube``), on a gently curved sheet, a paraboloid of sag a tenth of its
side (``sheet``, a net's shape) and on a plane (``plane``).

The table (``summary.md``): for each promised tolerance, the fastest library
eps whose worst error over every geometry, N, seed and property, times
``--safety``, is within the tolerance (FMM3D's time is not monotone in eps on
sheets, so the choice is by time among those that qualify).

Memory (``split_memory.csv``, ``--split-memory``): the ``fmm`` backend's
call (E+F) with ``ASE_MAUD_FMM_WORKERS`` 1 and 2, each in a fresh process,
its wall seconds and the peak memory of that process and its workers (their
summed proportional set size, sampled every 0.1 s from this process, so a
call that holds the GIL is sampled too): where splitting a call still pays
(``fmm.POOL_MAX_POINTS``).

Split (``split.csv``, ``--split-eps``): one process (``lfmm3d`` with all
points) against two worker processes (fork), each with all sources and the
targets of one half of space (split at the median of the longest axis),
interleaved repeats, wall and CPU seconds (the workers' own CPU summed), and
the 2-thread numba direct sum's wall for scale. The machine's load average
is saved with the figures: on cores other jobs use a second process gains
less than on free cores.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=2 \\
        python benchmarks/fmm_threads.py --out fmm_threads_run
"""

from __future__ import annotations

import argparse
import csv
import multiprocessing
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numba
import numpy as np
from fmm3dpy import lfmm3d  # the benchmark is of fmm3dpy itself

from ase_maud.backends import auto, direct, fmm
from ase_maud.bench.memory import tree_pss_kb
from ase_maud.counting import cpu_seconds
from ase_maud.scenes.catalogue import build

GEOMETRIES = ('cube', 'sheet', 'plane', 'net')
SIZES = (20000, 60000)
LIB_EPS = (1e-1, 3e-2, 1e-2, 3e-3, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
#: Promised force errors (relative to the largest force) to map.
TOLERANCES = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
SPLIT_EPS = (1e-2, 1e-4, 1e-6)


def scene(geometry: str, n: int, seed: int) -> np.ndarray:
    """``n`` random points at unit density of the named geometry."""
    if geometry == 'net':   # the flat start of a hanging net: a grid
        return build('hanging_net', round(np.sqrt(n)), seed=seed).positions
    rng = np.random.default_rng(seed)
    p = np.zeros((n, 3))
    if geometry == 'cube':
        return rng.uniform(0, n ** (1 / 3), (n, 3))
    side = np.sqrt(n)
    p[:, :2] = rng.uniform(0, side, (n, 2))
    if geometry == 'sheet':   # a paraboloid of sag side / 10
        r2 = ((p[:, :2] - side / 2) ** 2).sum(axis=1)
        p[:, 2] = 0.1 * side * (1 - r2 / (side / 2) ** 2 / 2)
    return p


def call(p, eps, order, targets=None):
    """lfmm3d's energy sum, forces and blocks (order 3) in the repulsion's
    units, at all points, or at ``targets`` (indices) from all points."""
    ones = np.ones(len(p))
    src = np.ascontiguousarray(p.T)
    if targets is None:
        out = lfmm3d(eps=eps, sources=src, charges=ones, pg=order)
        pot, grad, hess = out.pot, out.grad, getattr(out, 'hess', None)
    else:
        out = lfmm3d(eps=eps, sources=src, charges=ones, pgt=order,
                     targets=np.ascontiguousarray(p[targets].T))
        pot, grad, hess = out.pottarg, out.gradtarg, getattr(out, 'hesstarg', None)
    return fmm._unscale(0.5 * pot.sum(), grad, hess if order == 3 else None)


def load_average() -> str:
    """The machine's load averages over 1, 5 and 15 minutes, as one string."""
    return ' '.join(open('/proc/loadavg').read().split()[:3])


def timed(function, *args):
    """``(result, wall s, CPU s of this process)``."""
    wall, cpu = time.perf_counter(), cpu_seconds()
    result = function(*args)
    return result, time.perf_counter() - wall, cpu_seconds() - cpu


def errors(sizes, seeds, eps_list, geometries, writer, rows):
    """Rows of the library's error and time against the direct sum."""
    for n in sizes:
        for geometry in geometries:
            for seed in seeds:
                p = scene(geometry, n, seed)
                (e0, f0, b0), wall, _ = timed(direct.evaluate, p, True)
                print(f'{geometry} N={n} seed={seed}: direct E+F+K {wall:.2f} s wall',
                      flush=True)
                fmax = np.linalg.norm(f0, axis=1).max()
                for eps in eps_list:
                    for order in (2, 3):
                        (e, f, b), wall, cpu = timed(call, p, eps, order)
                        row = {'geometry': geometry, 'n': n, 'seed': seed,
                               'lib_eps': eps,
                               'computes': 'E+F+K' if order == 3 else 'E+F',
                               'force_error': np.linalg.norm(f - f0, axis=1).max() / fmax,
                               'energy_error': abs(e / e0 - 1),
                               'block_error': (np.abs(b - b0).max() / np.abs(b0).max()
                                               if order == 3 else ''),
                               'wall_s': wall, 'cpu_s': cpu}
                        writer.writerow(row)
                        rows.append(row)
                        print({k: (f'{v:.3g}' if isinstance(v, float) else v)
                               for k, v in row.items()}, flush=True)


def choose(rows, tolerances, safety):
    """``{tol: (lib_eps, worst error, seconds summed)}``: the fastest eps
    whose worst error times ``safety`` is within ``tol``."""
    worst, seconds = {}, {}
    for row in rows:
        eps = row['lib_eps']
        error = max(row['force_error'], row['energy_error'],
                    row['block_error'] or 0.0)
        worst[eps] = max(worst.get(eps, 0.0), error)
        seconds[eps] = seconds.get(eps, 0.0) + row['cpu_s']
    table = {}
    for tol in tolerances:
        ok = [eps for eps in worst if safety * worst[eps] <= tol]
        if ok:
            best = min(ok, key=lambda eps: seconds[eps])
            table[tol] = (best, worst[best], seconds[best])
    return table, worst, seconds


def table_lines(rows, safety):
    """Markdown: worst error and CPU by library eps (and by geometry), and
    the fastest eps for each tolerance (:func:`choose`)."""
    table, worst, seconds = choose(rows, TOLERANCES, safety)
    by_kind = {}
    for row in rows:
        key = row['lib_eps'], row['geometry']
        by_kind[key] = max(by_kind.get(key, 0.0), row['force_error'])
    kinds = sorted({row['geometry'] for row in rows})
    lines = ['| lib eps | worst error (force, energy, blocks) | CPU s summed | '
             + ' | '.join(f'{k}: force error' for k in kinds) + ' |',
             '|---|---|---|' + '---|' * len(kinds)]
    lines += [f'| {e:g} | {worst[e]:.2g} | {seconds[e]:.1f} | '
              + ' | '.join(f'{by_kind.get((e, k), float("nan")):.2g}' for k in kinds)
              + ' |' for e in sorted(worst)]
    return lines + ['', f'Fastest library eps with worst error x {safety:g} <= tol:', '',
                    '| tol | lib eps | worst error |', '|---|---|---|'] + [
        f'| {t:g} | {e:g} | {w:.2g} |' for t, (e, w, _) in table.items()]


def _half(args):
    """A worker's share: all sources, the targets given; with its CPU s."""
    p, eps, order, targets = args
    start = cpu_seconds()
    result = call(p, eps, order, targets)
    return result, cpu_seconds() - start


def split_halves(p):
    """Indices of the two halves of space, at the median of the longest
    axis."""
    axis = int(np.argmax(np.ptp(p, axis=0)))
    order = np.argsort(p[:, axis], kind='stable')
    half = len(p) // 2
    return np.sort(order[:half]), np.sort(order[half:])


def two_processes(pool, p, eps, order):
    """Energy, forces, blocks by two workers; and their CPU s summed."""
    halves = split_halves(p)
    parts = list(pool.map(_half, [(p, eps, order, h) for h in halves]))
    forces = np.empty((len(p), 3))
    blocks = np.empty((len(p), 6)) if order == 3 else None
    energy = 0.0
    for h, ((e, f, b), _) in zip(halves, parts, strict=True):
        energy += e
        forces[h] = f
        if order == 3:
            blocks[h] = b
    return (energy, forces, blocks), sum(cpu for _, cpu in parts)


def split(sizes, eps_list, repeats, geometries, writer):
    """Rows: one process against two, interleaved, and the direct sum."""
    context = multiprocessing.get_context('fork')
    with ProcessPoolExecutor(2, mp_context=context) as pool:
        pool.map(_half, [(scene('cube', 50, 0), 1e-3, 2, np.arange(5))] * 2)
        for n in sizes:
            for geometry in geometries:
                p = scene(geometry, n, 0)
                _, direct_wall, direct_cpu = timed(direct.evaluate, p, False)
                rows = {'direct 2 threads': [(direct_wall, direct_cpu)]}
                for eps in eps_list:
                    for order in (2, 3):
                        key = f'{eps:g} {"E+F+K" if order == 3 else "E+F"}'
                        for _ in range(repeats):
                            one, wall, cpu = timed(call, p, eps, order)
                            rows.setdefault(f'one {key}', []).append((wall, cpu))
                            (two, cpu2), wall, _ = timed(two_processes, pool, p,
                                                         eps, order)
                            rows.setdefault(f'two {key}', []).append((wall, cpu2))
                            diff = (np.abs(two[1] - one[1]).max()
                                    / np.abs(one[1]).max())
                            assert diff < 1e-12, diff   # the same sums
                for name, times in rows.items():
                    walls = sorted(t[0] for t in times)
                    row = {'geometry': geometry, 'n': n, 'what': name,
                           'wall_s_min': walls[0],
                           'wall_s_median': walls[len(walls) // 2],
                           'cpu_s_min': min(t[1] for t in times),
                           'load': load_average()}
                    writer.writerow(row)
                    print(row, flush=True)


def _one_call(geometry, n, eps):
    """In a fresh process: the backend's E+F call at ``fmm_eps = eps`` on
    ``n`` points of ``geometry`` (workers started by a call of 3x10^4 points
    first); prints its wall seconds."""
    p = scene(geometry, n, 0)
    fmm.evaluate(p[:30000], False, eps)
    _, wall, _ = timed(fmm.evaluate, p, False, eps)
    print(wall)


def split_memory(sizes, eps_list, geometries, writer):
    """Rows: wall seconds and peak memory of one call with one worker
    process and with two, each call in a fresh process."""
    for n in sizes:
        for geometry in geometries:
            for eps in eps_list:
                for count in (2, 1):
                    child = subprocess.Popen(
                        [sys.executable, __file__, '--one-call', geometry, str(n), str(eps)],
                        stdout=subprocess.PIPE, text=True,
                        env={**os.environ, fmm.WORKERS_VARIABLE: str(count)})
                    peak = 0.0
                    while child.poll() is None:
                        peak = max(peak, tree_pss_kb(child.pid) / 1024)
                        time.sleep(0.1)
                    row = {'geometry': geometry, 'n': n, 'fmm_eps': eps, 'workers': count,
                           'wall_s': float(child.stdout.read()), 'peak_mb': round(peak),
                           'load': load_average()}
                    writer.writerow(row)
                    print(row, flush=True)


def goal(geometry, n, tol, repeats):
    """Wall s of ``auto`` at ``tol``, of the numba direct sum and of the
    ``fmm`` backend at ``fmm_eps = tol`` (E+F) on ``n`` points of
    ``geometry``, best of ``repeats`` interleaved, and the backend auto
    took."""
    p = scene(geometry, n, 0)
    auto.evaluate(p, False, tol=tol)
    best = {'auto': np.inf, 'numba': np.inf, 'fmm': np.inf}
    for _ in range(repeats):
        best['auto'] = min(best['auto'], timed(auto.evaluate, p, False, tol)[1])
        best['numba'] = min(best['numba'], timed(direct.evaluate, p, False)[1])
        best['fmm'] = min(best['fmm'], timed(fmm.evaluate, p, False, tol)[1])
    dim = 2 if np.ptp(p[:, 2]) == 0 else 3
    return best, auto.choose(len(p), dim, False, tol)[0].backend.name


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path,
                        help='a new directory for the raw numbers')
    parser.add_argument('--sizes', type=int, nargs='+', default=SIZES)
    parser.add_argument('--geometries', nargs='+', default=GEOMETRIES,
                        choices=GEOMETRIES)
    parser.add_argument('--seeds', type=int, nargs='+', default=(0, 1))
    parser.add_argument('--eps', type=float, nargs='+', default=LIB_EPS)
    parser.add_argument('--safety', type=float, default=10.0)
    parser.add_argument('--split-eps', type=float, nargs='*', default=SPLIT_EPS)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--no-errors', action='store_true')
    parser.add_argument('--goal', type=int, default=60000,
                        help='N for auto at tol 1e-4 against the direct sum (0: skip)')
    parser.add_argument('--combine', type=Path, nargs='+',
                        help="earlier runs' errors.csv: their table only")
    parser.add_argument('--split-memory', type=float, nargs='*', default=(),
                        help='fmm_eps of the one-against-two memory rows')
    parser.add_argument('--one-call', nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one_call:
        geometry, n, eps = args.one_call
        _one_call(geometry, int(n), float(eps))
        return
    if args.combine:
        rows = [{**row, **{k: float(row[k] or 0.0) for k in (
            'lib_eps', 'force_error', 'energy_error', 'block_error', 'cpu_s')}}
            for path in args.combine for row in csv.DictReader(open(path))]
        print('\n'.join(table_lines(rows, args.safety)))
        return
    if args.out is None or args.out.exists():
        parser.error(f'--out {args.out} exists or is missing: give a new directory')
    args.out.mkdir(parents=True)
    direct.evaluate(scene('cube', 10, 0), True)   # compile or load the kernels
    head = (f'Measured {time.strftime("%Y-%m-%d %H:%M")}, numba threads '
            f'{numba.get_num_threads()}, fmm3dpy one thread a process, '
            f'{len(os.sched_getaffinity(0))} cores; load at start '
            f'{load_average()}: `'
            + ' '.join(f'{v}={os.environ[v]}' for v in
                       ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'NUMBA_NUM_THREADS')
                       if v in os.environ)
            + f' python benchmarks/fmm_threads.py {" ".join(sys.argv[1:])}`')
    lines = [f'# fmm3dpy: eps, error, time; one process against two\n\n{head}\n']
    if not args.no_errors:
        rows = []
        with open(args.out / 'errors.csv', 'w', newline='') as file:
            writer = csv.DictWriter(file, ['geometry', 'n', 'seed', 'lib_eps', 'computes',
                                           'force_error', 'energy_error', 'block_error',
                                           'wall_s', 'cpu_s'])
            writer.writeheader()
            errors(args.sizes, args.seeds, args.eps, args.geometries, writer, rows)
        lines += table_lines(rows, args.safety) + ['']
    if args.split_eps:
        with open(args.out / 'split.csv', 'w', newline='') as file:
            writer = csv.DictWriter(file, ['geometry', 'n', 'what', 'wall_s_min',
                                           'wall_s_median', 'cpu_s_min', 'load'])
            writer.writeheader()
            split(args.sizes, args.split_eps, args.repeats, args.geometries, writer)
        lines.append('Split: see split.csv (wall and CPU seconds, one process '
                     'against two).\n')
    if args.split_memory:
        with open(args.out / 'split_memory.csv', 'w', newline='') as file:
            writer = csv.DictWriter(file, ['geometry', 'n', 'fmm_eps', 'workers', 'wall_s',
                                           'peak_mb', 'load'])
            writer.writeheader()
            split_memory(args.sizes, args.split_memory, args.geometries, writer)
        lines.append('Memory: see split_memory.csv (one call, one worker process '
                     'against two).\n')
    for geometry in args.geometries if args.goal else ():
        best, took = goal(geometry, args.goal, 1e-4, args.repeats)
        lines.append(f'Goal: {geometry}, N = {args.goal}, E+F, tol 1e-4: auto '
                     f'({took}) {best["auto"]:.3g} s wall, numba direct sum on '
                     f'{numba.get_num_threads()} threads {best["numba"]:.3g} s: '
                     f'{best["auto"] / best["numba"]:.2f}x; the fmm backend at fmm_eps '
                     f'1e-4 {best["fmm"]:.3g} s, {best["fmm"] / best["numba"]:.2f}x (fmm threads '
                     f'{fmm.threads()}, load {load_average()}).\n')
    lines.append(f'Load at end: {load_average()}')
    text = '\n'.join(lines) + '\n'
    (args.out / 'summary.md').write_text(text)
    print(text)


if __name__ == '__main__':
    main()
