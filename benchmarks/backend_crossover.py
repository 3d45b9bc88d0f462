"""Where the FMM beats the direct sum, and how exact it is: the numbers
behind ``backend='auto'`` (ase_maud.backends.auto.CROSSOVER and
ase_maud.backends.fmm.FORCE_ERROR_PER_EPS).

Timing: seconds per call of the numba direct sum and of the FMM at several
``fmm_eps``, for energy + forces (E+F) and with the nodal blocks (E+F+K), on
N random points of unit density in a cube (dim 3) or a square (dim 2). The
direct sum is timed up to ``--direct-max`` points and fitted as ``alpha
N**2`` beyond; the crossover is the N where the FMM's time (interpolated
log-log, extrapolated linearly past the last N) meets it. The clock is CPU
time when both run on one thread (``NUMBA_NUM_THREADS=1``,
``ASE_MAUD_FMM_WORKERS=1`` and ``ASE_MAUD_FMM_THREADS`` unset: the numbers
of ``auto.CROSSOVER``), else
wall time (to check how the crossover moves with threads).

Errors (``--errors``): the FMM's largest force error (norm over points),
relative to the largest force, against the exact direct sum, over seeds, on
a cube, a plane, the start of a hanging net (a flat sheet whose forces
nearly cancel: the worst case seen), a cube with one pair at 1e-13 of its
size and two clusters far apart; the largest ratio to ``fmm_eps`` sets
FORCE_ERROR_PER_EPS.

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
        ASE_MAUD_FMM_WORKERS=1 python benchmarks/backend_crossover.py --errors \
        --out docs/dev/bench/crossover_backends.md
    NUMBA_NUM_THREADS=2 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
        python benchmarks/backend_crossover.py --out crossover_2threads.md
"""

import argparse
import sys
import time
from functools import partial
from pathlib import Path

import numba
import numpy as np

from ase_maud.backends import direct, fmm
from ase_maud.counting import cpu_seconds
from ase_maud.scenes.catalogue import build

EPS = (1e-3, 1e-5, 1e-6, 1e-8, 1e-9, 1e-12)
SIZES = (2000, 4000, 8000, 16000, 32000, 64000)


def points(n, dim, seed=0):
    """``n`` points uniform at unit density in a cube (dim 3) or square."""
    rng = np.random.default_rng(seed)
    p = np.zeros((n, 3))
    p[:, :dim] = rng.uniform(0, n ** (1 / dim), (n, dim))
    return p


def cpu_clock():
    """Whether to time by CPU time: if the direct sum and the FMM each run
    on one thread (it does not count the time others' processes take; else
    wall time)."""
    return numba.get_num_threads() == 1 and fmm.threads() == 1


def clock():
    """Seconds by the clock :func:`cpu_clock` says."""
    return cpu_seconds() if cpu_clock() else time.perf_counter()


def seconds(evaluate, repeats):
    """Best time (:func:`clock`) of ``repeats`` calls after one warm-up
    call."""
    evaluate()
    best = np.inf
    for _ in range(repeats):
        start = clock()
        evaluate()
        best = min(best, clock() - start)
    return best


def crossover(sizes, t_fmm, alpha):
    """N where ``t_fmm`` (measured at ``sizes``) meets ``alpha N**2``."""
    ratio = np.asarray(t_fmm) / (alpha * np.asarray(sizes, float) ** 2)
    if ratio[0] <= 1:
        return sizes[0]
    for k in range(1, len(sizes)):
        if ratio[k] <= 1:  # log-log interpolation of ratio = 1
            x0, x1 = np.log(sizes[k - 1]), np.log(sizes[k])
            y0, y1 = np.log(ratio[k - 1]), np.log(ratio[k])
            return float(np.exp(x0 - y0 * (x1 - x0) / (y1 - y0)))
    return t_fmm[-1] / (alpha * sizes[-1])   # FMM linear beyond


def fmm_seconds(p, blocks, eps, repeats):
    """CPU seconds per FMM call, inf if it refuses the scene (too many near
    points at this eps: ``auto`` would use the direct sum)."""
    try:
        return seconds(partial(fmm.evaluate, p, blocks, fmm_eps=eps), repeats)
    except fmm.BeyondTolerance:
        return np.inf


def timing(sizes, direct_max, repeats, dims):
    """Rows of seconds per call, and crossover[(dim, blocks)][eps]."""
    rows, table = [], {}
    for dim in dims:
        for blocks in (False, True):
            alphas = []
            fmm_times = {eps: [] for eps in EPS}
            for n in sizes:
                p = points(n, dim)
                if n <= direct_max:
                    t = seconds(partial(direct.evaluate, p, blocks), repeats)
                    alphas.append(t / n**2)
                    rows.append((dim, blocks, n, 'numba', t))
                for eps in EPS:
                    t = fmm_seconds(p, blocks, eps, repeats if n < 20000 else 1)
                    fmm_times[eps].append(t)
                    rows.append((dim, blocks, n, f'fmm {eps:g}', t))
                print(*rows[-len(EPS) - 1:], sep='\n', flush=True)
            alpha = float(np.median(alphas[len(alphas) // 2:]))
            rows.append((dim, blocks, 0, 'numba fit alpha', alpha))
            table[dim, blocks] = {eps: crossover(sizes, fmm_times[eps], alpha)
                                  for eps in EPS}
            print(dim, blocks, table[dim, blocks], flush=True)
    return rows, table


def error_scenes(n, seed):
    """Named scenes of ``n`` points for the error table."""
    rng = np.random.default_rng(seed)
    cube = rng.uniform(0, 1, (n, 3))
    plane = cube.copy()
    plane[:, 2] = 0
    near = cube.copy()
    near[1] = near[0] + 1e-13 * rng.standard_normal(3)
    side = max(int(round(np.sqrt(n))), 3)
    net = build('hanging_net', side, seed=seed).positions
    far = cube.copy()
    far[n // 2:, 0] += 1e3
    farther = cube.copy()
    farther[n // 2:, 0] += 1e6
    return {'cube': cube, 'plane': plane, 'hanging net (its start)': net,
            'pair at 1e-13': near,
            'clusters 1e3 apart': far, 'clusters 1e6 apart': farther}


def errors(n, seeds, eps_list):
    """Largest force error / largest force, and its ratio to eps."""
    lines = ['| scene | fmm_eps | largest force error / largest force '
             f'(max over {len(seeds)} seeds) | / fmm_eps | blocks: largest '
             'error / largest entry |', '|---|---|---|---|---|']
    worst = 0.0
    table = {}
    for seed in seeds:
        for name, p in error_scenes(n, seed).items():
            _, f0, b0 = direct.evaluate(p, True)
            for eps in eps_list:
                try:
                    _, f, b = fmm.evaluate(p, True, fmm_eps=eps)
                except fmm.BeyondTolerance:  # too many near points
                    table[name, eps] = None
                    continue
                norm = np.linalg.norm
                f_err = norm(f - f0, axis=1).max() / norm(f0, axis=1).max()
                b_err = np.abs(b - b0).max() / np.abs(b0).max()
                old = table.get((name, eps), (0.0, 0.0))
                if old is not None:
                    table[name, eps] = max(old[0], f_err), max(old[1], b_err)
    for (name, eps), value in table.items():
        if value is None:
            lines.append(f'| {name} | {eps:g} | refused | | |')
            continue
        worst = max(worst, value[0] / eps)
        lines.append(f'| {name} | {eps:g} | {value[0]:.2g} | '
                     f'{value[0] / eps:.2g} | {value[1]:.2g} |')
    lines.append(f'\nLargest ratio: {worst:.2g} (FORCE_ERROR_PER_EPS = '
                 f'{fmm.FORCE_ERROR_PER_EPS:g}). Refused: more than '
                 f'{fmm.MAX_NEAR_POINTS} points closer than the near radius '
                 '(auto then uses the direct sum).')
    print(*lines, sep='\n', flush=True)
    return lines


def timing_section(rows, table):
    """Markdown: the crossover table, as CROSSOVER, and the seconds."""
    lines = ['## Crossover N (FMM faster above it), numba threads '
             f'{numba.get_num_threads()}, FMM threads {fmm.threads()}', '',
             '| dim | computes | ' + ' | '.join(f'fmm_eps {e:g}' for e in EPS)
             + ' |', '|---|---|' + '---|' * len(EPS)]
    for (dim, blocks), row in table.items():
        lines.append(f'| {dim} | {"E+F+K" if blocks else "E+F"} | '
                     + ' | '.join(f'{row[e]:.0f}' for e in EPS) + ' |')
    if cpu_clock():   # one thread each: the layout of auto.CROSSOVER
        lines += ['', 'As ase_maud.backends.auto.CROSSOVER:', '', '```python',
                  '{' + ',\n '.join(
                      f'({d}, {b}): {{' + ', '.join(
                          f'{e:g}: {round(v, -2):.0f}' for e, v in row.items())
                      + '}' for (d, b), row in table.items()) + '}', '```']
    lines += ['', f'## {"CPU" if cpu_clock() else "Wall"} seconds per call', '',
              '| dim | computes | N | backend | seconds |', '|---|---|---|---|---|']
    return lines + [f'| {d} | {"E+F+K" if b else "E+F"} | {n} | {name} | {t:.4g} |'
                    for d, b, n, name, t in rows]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=SIZES)
    parser.add_argument('--direct-max', type=int, default=16000)
    parser.add_argument('--dims', type=int, nargs='+', default=(3, 2))
    parser.add_argument('--repeats', type=int, default=2)
    parser.add_argument('--errors', action='store_true',
                        help='also measure the error table')
    parser.add_argument('--no-timing', action='store_true',
                        help='only the error table')
    parser.add_argument('--error-points', type=int, default=5000)
    parser.add_argument('--out', type=Path, help='markdown to write')
    args = parser.parse_args()
    direct.evaluate(points(10, 3), True)   # compile or load the kernels
    lines = []
    if args.errors:
        lines += ['## FMM force error against fmm_eps', '',
                  f'{args.error_points} points, seeds 0-2, against the numba '
                  'direct sum.', '']
        lines += errors(args.error_points, range(3), EPS) + ['']
    if not args.no_timing:
        lines += timing_section(*timing(args.sizes, args.direct_max,
                                        args.repeats, args.dims))
    threads, fmm_threads = numba.get_num_threads(), fmm.library_threads()
    declared = (f'{fmm.THREADS_VARIABLE}={fmm_threads} ' if fmm_threads > 1
                else '') + f'{fmm.WORKERS_VARIABLE}={fmm.workers()} '
    header = (f'# Backend crossovers\n\nMeasured {time.strftime("%Y-%m-%d")}, '
              f'numba threads {threads}, FMM threads {fmm.threads()}: '
              f'`NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={fmm_threads} '
              f'{declared}OPENBLAS_NUM_THREADS=1 python '
              f'benchmarks/backend_crossover.py {" ".join(sys.argv[1:])}`\n\n')
    text = header + '\n'.join(lines) + '\n'
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == '__main__':
    main()
