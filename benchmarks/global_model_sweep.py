"""The global model's settings: L-BFGS ``memory`` and ``refresh`` (how far points
may move before ``P`` is rebuilt), calculator calls and CPU seconds to an fmax
on larger scenes. docs/optimizer.md quotes the output.

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
        python benchmarks/global_model_sweep.py --out docs/dev/bench/global_model_sweep.md
"""

import argparse
import time
from pathlib import Path

from ase_maud import Maud
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.optimize.models.global_model import GlobalModel
from ase_maud.scenes.catalogue import build

SCENES = [('chain', 20), ('ring', 100), ('hanging_net', 20), ('random_graph', 200),
          ('hanging_net', 50)]
VARIANTS = [(0, 0.5), (10, 0.5), (30, 0.5), (30, 0.0), (30, 0.1), (30, 1.0), (30, 2.0)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--out', type=Path, help='markdown table to write')
    args = parser.parse_args()
    lines = ['| scene | N | memory | refresh | calls | CPU s | energy |',
             '|---|---|---|---|---|---|---|']
    for name, size in SCENES:
        for memory, refresh in VARIANTS:
            atoms = build(name, size, seed=args.seed)
            opt = Maud(atoms, model=GlobalModel(refresh=refresh), memory=memory, logfile=None)
            calls, cpu, done = calls_and_cpu(atoms, opt, args.fmax, 3000)
            row = (f'| {name} | {len(atoms)} | {memory} | {refresh:g} | '
                   f'{calls}{"" if done else " (not conv.)"} | {cpu:.2f} | '
                   f'{atoms.get_potential_energy():.10g} |')
            print(row, flush=True)
            lines.append(row)
    if args.out:
        args.out.write_text(
            f'Measured {time.strftime("%Y-%m-%d")}, fmax {args.fmax:g}, seed {args.seed}, '
            'one thread: `python benchmarks/global_model_sweep.py`\n\n' + '\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
