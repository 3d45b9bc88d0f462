"""Throughput of the direct-sum repulsion against a plain loop, side by side.

For each size N the production kernel (``ase_maud.backends.direct``, energy
and forces, and energy, forces and nodal blocks) is timed in the same run as a
plain numba loop over every ordered pair (the yardstick, defined here and
nowhere in the package: ``prange`` over rows, an inner loop over every ``j``
that skips ``j == i``, no symmetry; the same compiler flags as the kernel).
A second yardstick, ``plain-vec``, is the same loop written so that LLVM
vectorises it (a select instead of the skip); it shows what vectorisation
alone buys. ``calculator`` adds a chain of springs and ASE's bookkeeping
(``MaudCalculator``), ``numpy`` is the reference at sizes up to
``--numpy-max``.

The calls are interleaved: every round calls each path once, and rounds
repeat until ``--seconds`` per size are spent (at least ``--rounds``), so a
busy machine slows every path alike. Reported: the best wall time, ordered
pairs a second ``N (N - 1) / t``, the ratio of the plain loop's best time to
the path's (and the median of the per-round ratios), and cycles per unordered
pair, ``threads * clock * t / (N (N - 1) / 2)``, with ``clock`` the mean
``cpu MHz`` of /proc/cpuinfo (the nominal clock: turbo and other tenants are
not seen). Raw numbers go to a CSV file, the table with date and command to a
Markdown file next to it.

    python benchmarks/kernel_throughput.py --threads 2 \
        --out docs/dev/bench/kernel/kernel_throughput.csv
"""

import argparse
import csv
import os
import platform
import shlex
import statistics
import sys
import time
from datetime import datetime, timezone
from functools import partial
from pathlib import Path

import numpy as np


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[1500, 6000, 12000],
                        help='numbers of points')
    parser.add_argument('--threads', type=int, default=2,
                        help='NUMBA_NUM_THREADS (set before numba is imported)')
    parser.add_argument('--seconds', type=float, default=20.0,
                        help='time spent on the rounds at each size')
    parser.add_argument('--rounds', type=int, default=3,
                        help='least number of rounds at each size')
    parser.add_argument('--numpy-max', type=int, default=2000,
                        help='largest size for the numpy reference')
    parser.add_argument('--out', default='kernel_throughput.csv',
                        help='CSV file for the raw numbers (the table goes to the same '
                        'name with .md)')
    return parser.parse_args()


def clock_mhz():
    """Mean ``cpu MHz`` of /proc/cpuinfo, or None where there is none."""
    try:
        lines = Path('/proc/cpuinfo').read_text().splitlines()
    except OSError:
        return None
    mhz = [float(line.split(':')[1]) for line in lines if line.startswith('cpu MHz')]
    return sum(mhz) / len(mhz) if mhz else None


def plain_loops():
    """The yardsticks: (E+F, E+F+K) plain loops over every ordered pair, and the
    same written so that LLVM vectorises them. Compiled here, after main() has
    set NUMBA_NUM_THREADS."""
    import numba

    def make(with_blocks, vectorised):
        @numba.njit(parallel=True, fastmath=True, error_model='numpy')
        def plain(x, y, z):
            n = x.size
            e = np.zeros(n)
            f = np.zeros((n, 3))
            k = np.zeros((n, 6))
            for i in numba.prange(n):
                ei = gx = gy = gz = 0.0
                bxx = byy = bzz = bxy = bxz = byz = 0.0
                for j in range(n):
                    if not vectorised and j == i:
                        continue
                    dx, dy, dz = x[i] - x[j], y[i] - y[j], z[i] - z[j]
                    inv = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
                    if vectorised and j == i:
                        inv = 0.0
                    inv3 = inv * inv * inv
                    ei += inv
                    px, py, pz = dx * inv3, dy * inv3, dz * inv3
                    gx += px
                    gy += py
                    gz += pz
                    if with_blocks:
                        s = 3.0 * inv * inv
                        bxx += s * dx * px - inv3
                        byy += s * dy * py - inv3
                        bzz += s * dz * pz - inv3
                        bxy += s * dx * py
                        bxz += s * dx * pz
                        byz += s * dy * pz
                e[i] = ei
                f[i, 0], f[i, 1], f[i, 2] = gx, gy, gz
                if with_blocks:
                    k[i, 0], k[i, 1], k[i, 2] = bxx, byy, bzz
                    k[i, 3], k[i, 4], k[i, 5] = bxy, bxz, byz
            return 0.5 * e.sum(), f, k

        return plain

    return {(name, blocks): make(blocks, vectorised)
            for name, vectorised in (('plain', False), ('plain-vec', True))
            for blocks in (False, True)}


def cases(n, numpy_max, plain):
    """{(path, blocks): callable} of every measurement at size ``n``."""
    from ase import Atoms

    from ase_maud.backends import direct, reference
    from ase_maud.calculator.maud_calculator import MaudCalculator

    positions = np.random.default_rng(n).uniform(0, n ** (1 / 3), (n, 3))
    xyz = [positions[:, k].copy() for k in range(3)]
    chain = np.c_[np.arange(n - 1), np.arange(1, n)]
    atoms = Atoms(f'H{n}', positions,
                  calculator=MaudCalculator(springs=chain, backend='numba'))
    calc = atoms.calc

    def through_calculator(blocks):
        calc.reset()  # forget the cached results: recompute every call
        return calc.get_stiffness(atoms) if blocks else atoms.get_forces()

    calls = {}
    for blocks in (False, True):
        for name in ('plain', 'plain-vec'):
            calls[name, blocks] = partial(plain[name, blocks], *xyz)
        calls['kernel', blocks] = partial(direct.evaluate, positions, blocks)
        calls['calculator', blocks] = partial(through_calculator, blocks)
        if n <= numpy_max:
            calls['numpy', blocks] = partial(reference.evaluate, positions, blocks)
    return calls


def check_agree(calls):
    """The yardsticks compute what the kernel does (energy and forces)."""
    energy, forces, _ = calls['kernel', False]()
    for name in ('plain', 'plain-vec'):
        e, f, _ = calls[name, False]()
        assert abs(e - energy) <= 1e-12 * energy, (name, e, energy)
        assert np.abs(f - forces).max() <= 1e-12 * np.abs(forces).max(), name


def measure(calls, seconds, rounds):
    """Interleaved rounds: {key: [(wall, cpu) per round]}."""
    times = {key: [] for key in calls}
    stop = time.perf_counter() + seconds
    done = 0
    while done < rounds or time.perf_counter() < stop:
        for key, call in calls.items():
            wall, cpu = time.perf_counter(), time.process_time()
            call()
            times[key].append((time.perf_counter() - wall, time.process_time() - cpu))
        done += 1
    return times


def main():
    args = parse_args()
    # numba reads NUMBA_NUM_THREADS when it is first imported; imported before
    # (a test calling main()), it can only lower the count it launched.
    if 'numba' not in sys.modules:
        os.environ['NUMBA_NUM_THREADS'] = str(args.threads)
    os.environ.setdefault('OMP_NUM_THREADS', str(args.threads))
    import numba

    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))

    from ase_maud.backends import direct

    for blocks in (False, True):  # compile, or load the cached machine code
        direct.evaluate(np.random.default_rng(0).normal(size=(64, 3)), blocks)
    plain = plain_loops()
    mhz = clock_mhz()
    threads = numba.get_num_threads()
    command = 'python ' + shlex.join(['benchmarks/kernel_throughput.py', *sys.argv[1:]])
    machine = (f'NUMBA_NUM_THREADS={threads} (threading layer {numba.threading_layer()}), '
               f'{os.cpu_count()} CPUs, clock {mhz or float("nan"):.0f} MHz (mean cpu MHz of '
               f'/proc/cpuinfo, assumed for cycles), numba {numba.__version__}, '
               f'numpy {np.__version__}, {platform.processor() or platform.machine()}')
    header = (f'| {"N":>6} | {"path":>10} | {"blocks":>6} | {"best ms":>9} | '
              f'{"ordered pairs/s":>15} | {"x plain":>7} | {"x plain, median":>15} | '
              f'{"x plain-vec":>11} | {"cycles/pair":>11} | {"rounds":>6} |')
    lines = [header, '|' + '|'.join('-' * (len(c)) for c in header.split('|')[1:-1]) + '|']
    print(machine)
    print('cycles/pair: threads * clock * best wall time per unordered pair')
    print('\n'.join(lines))
    rows = []
    for n in args.sizes:
        calls = cases(n, args.numpy_max, plain)
        check_agree(calls)
        times = measure(calls, args.seconds, args.rounds)
        for (path, blocks), samples in times.items():
            best = min(wall for wall, _ in samples)
            per_round = [p[0] / s[0] for p, s in zip(times['plain', blocks], samples,
                                                      strict=True)]
            row = {'n': n, 'path': path, 'blocks': blocks, 'threads': threads,
                   'rounds': len(samples), 'best_seconds': best,
                   'best_cpu_seconds': min(cpu for _, cpu in samples),
                   'ordered_pairs_per_second': n * (n - 1) / best,
                   'ratio_to_plain': min(w for w, _ in times['plain', blocks]) / best,
                   'median_round_ratio_to_plain': statistics.median(per_round),
                   'ratio_to_plain_vec': min(w for w, _ in times['plain-vec', blocks]) / best,
                   'cycles_per_unordered_pair': (threads * mhz * 1e6 * best / (n * (n - 1) / 2)
                                                 if mhz else float('nan')),
                   'clock_mhz': mhz}
            rows.append(row)
            line = (f'| {n:6d} | {path:>10} | {"yes" if blocks else "no":>6} | '
                    f'{best * 1e3:9.2f} | {row["ordered_pairs_per_second"]:15.3g} | '
                    f'{row["ratio_to_plain"]:7.2f} | {row["median_round_ratio_to_plain"]:15.2f} | '
                    f'{row["ratio_to_plain_vec"]:11.2f} | '
                    f'{row["cycles_per_unordered_pair"]:11.1f} | {len(samples):6d} |')
            lines.append(line)
            print(line, flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, 'w', newline='') as fd:
        writer = csv.DictWriter(fd, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    date = datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    out.with_suffix('.md').write_text(
        f'# Direct kernel against a plain loop\n\n{date}\n\n    {command}\n\n{machine}.\n'
        'cycles/pair = threads * clock * best wall time per unordered pair; "x plain" is the '
        "plain loop's best time over the path's; \"median\" is the median of the per-round "
        'ratios.\n\n' + '\n'.join(lines) + '\n')
    print(f'raw numbers written to {out}, the table to {out.with_suffix(".md")}')


if __name__ == '__main__':
    main()
