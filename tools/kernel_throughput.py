"""Throughput of the direct-sum repulsion: ordered pair interactions a second.

The rate is ``N (N - 1) / t``, with ``t`` the best wall time of one call among
the calls that fit in ``--seconds`` (at least one). Measured for energy and
forces, and for energy, forces and nodal blocks, through the kernel
(``ase_maud.backends.direct``) and through ``MaudCalculator`` (with a chain of
springs and ASE's bookkeeping), and for the numpy reference at sizes up to
``--numpy-max``. Thread counts are printed with the table; raw numbers go to a
CSV file.

    python tools/kernel_throughput.py --sizes 1000 4000 --threads 2
"""

import argparse
import csv
import os
import platform
import time
from functools import partial

import numpy as np


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+',
                        default=[1000, 4000, 16000], help='numbers of points')
    parser.add_argument('--threads', type=int, default=2,
                        help='NUMBA_NUM_THREADS (set before numba is imported)')
    parser.add_argument('--seconds', type=float, default=3.0,
                        help='time spent on each measurement')
    parser.add_argument('--numpy-max', type=int, default=4000,
                        help='largest size for the numpy reference')
    parser.add_argument('--out', default='kernel_throughput.csv',
                        help='CSV file for the raw numbers')
    return parser.parse_args()


def best_time(call, seconds):
    """Best wall time of ``call()`` over repeats filling ``seconds``."""
    times = []
    stop = time.perf_counter() + seconds
    while not times or time.perf_counter() < stop:
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times), len(times)


def cases(n, numpy_max):
    """(path, blocks, callable) for every measurement at size ``n``.

    Imports here, not at the top: numba must load after main() has set
    NUMBA_NUM_THREADS.
    """
    from ase import Atoms

    from ase_maud.backends import direct, reference
    from ase_maud.calculator import MaudCalculator

    positions = np.random.default_rng(n).uniform(0, n ** (1 / 3), (n, 3))
    chain = np.c_[np.arange(n - 1), np.arange(1, n)]
    atoms = Atoms(f'H{n}', positions, calculator=MaudCalculator(springs=chain))
    calc = atoms.calc

    def through_calculator(blocks):
        calc.reset()  # forget the cached results: recompute every call
        return calc.get_stiffness(atoms) if blocks else atoms.get_forces()

    for blocks in (False, True):
        yield 'kernel', blocks, partial(direct.evaluate, positions, blocks)
        yield 'calculator', blocks, partial(through_calculator, blocks)
        if n <= numpy_max:
            yield 'numpy', blocks, partial(reference.evaluate, positions, blocks)


def main():
    args = parse_args()
    # numba reads NUMBA_NUM_THREADS once, when it is first imported.
    os.environ['NUMBA_NUM_THREADS'] = str(args.threads)
    os.environ.setdefault('OMP_NUM_THREADS', str(args.threads))
    import numba

    from ase_maud.backends import direct

    for blocks in (False, True):  # compile, or load the cached machine code
        direct.evaluate(np.random.default_rng(0).normal(size=(64, 3)), blocks)

    print(f'NUMBA_NUM_THREADS={numba.get_num_threads()} '
          f'(threading layer {numba.threading_layer()}), '
          f'OMP_NUM_THREADS={os.environ["OMP_NUM_THREADS"]}, '
          f'{os.cpu_count()} CPUs, numba {numba.__version__}, '
          f'numpy {np.__version__}, {platform.processor() or platform.machine()}')
    print('ordered pair interactions per second, N (N - 1) / best time:')
    header = f'{"N":>7} {"path":>11} {"E+F":>10} {"E+F+K":>10}'
    print(header)
    print('-' * len(header))
    rows = []
    for n in args.sizes:
        rates = {}
        for path, blocks, call in cases(n, args.numpy_max):
            seconds, calls = best_time(call, args.seconds)
            rate = n * (n - 1) / seconds
            rates[path, blocks] = rate
            rows.append({'n': n, 'path': path, 'blocks': blocks,
                         'numba_threads': numba.get_num_threads(),
                         'omp_threads': os.environ['OMP_NUM_THREADS'],
                         'calls': calls, 'best_seconds': seconds,
                         'pairs_per_second': rate})
        for path in ('kernel', 'calculator', 'numpy'):
            if (path, False) in rates:
                print(f'{n:7d} {path:>11} {rates[path, False]:10.3g} '
                      f'{rates[path, True]:10.3g}')
    with open(args.out, 'w', newline='') as fd:
        writer = csv.DictWriter(fd, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f'raw numbers written to {args.out}')


if __name__ == '__main__':
    main()
