"""Calls and CPU seconds of Maud (default model) against SciPy's L-BFGS-B on
hanging nets of growing size, to an fmax (in Q a). docs/benchmarks.md quotes
the output.

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
        python tools/hanging_net_scaling.py --sizes 20 50 100 --out docs/bench/hanging_nets.md
"""

import argparse
import time
from pathlib import Path

from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.scenes import build


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[20, 50, 100],
                        help='grid sides (N = side**2 points)')
    parser.add_argument('--optimizers', nargs='+', default=['Maud', 'L-BFGS-B'],
                        choices=OPTIMIZERS)
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--out', type=Path, help='markdown table to write')
    args = parser.parse_args()
    lines = ['| N | optimiser | converged | calls | CPU s | energy |',
             '|---|---|---|---|---|---|']
    for size in args.sizes:
        for name in args.optimizers:
            atoms = build('hanging_net', size, seed=args.seed)
            calls, cpu, done = calls_and_cpu(atoms, OPTIMIZERS[name](atoms), args.fmax,
                                             args.steps)
            row = (f'| {len(atoms)} | {name} | {done} | {calls} | {cpu:.1f} | '
                   f'{atoms.get_potential_energy():.10g} |')
            print(row, flush=True)
            lines.append(row)
    if args.out:
        sizes = ' '.join(map(str, args.sizes))
        args.out.write_text(
            f'Measured {time.strftime("%Y-%m-%d")}, fmax {args.fmax:g}, seed {args.seed}, one '
            f'thread: `python tools/hanging_net_scaling.py --sizes {sizes}`'
            '\n\n' + '\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
