"""What a restart file costs: Maud (default model) relaxing a scene to
``--fmax`` with and without ``restart=``, runs interleaved, ``--repeats``
times each; the median wall seconds of each and their ratio, and the size of
the restart files. The state is written after every step (docs/hard_cases.md)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/restart_overhead.py --out docs/dev/bench/restart_overhead.md
"""

from __future__ import annotations

import argparse
import datetime
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


def one_run(name: str, size: int, fmax: float, restart: Path | None) -> tuple[float, int]:
    """Wall seconds and steps of one relaxation from seed 0."""
    atoms = build(name, size)
    start = time.perf_counter()
    with Maud(atoms, logfile=None, restart=restart) as opt:
        opt.run(fmax=fmax)
    return time.perf_counter() - start, opt.nsteps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=['hanging_net:20', 'hanging_net:50',
                                                        'hanging_net:100'])
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    one_run('hanging_net', 4, 1e-3, None)   # kernels compiled or loaded
    lines = [f'Measured {datetime.date.today()}, one thread, fmax {args.fmax:g} Q a, '
             f'medians of {args.repeats} interleaved runs each: '
             f'`python benchmarks/restart_overhead.py {" ".join(sys.argv[1:])}`', '',
             '| scene | N | steps | without s | with restart= s | ratio | restart files kB |',
             '|---|---|---|---|---|---|---|']
    for scene in args.scenes:
        name, size = scene.split(':')
        plain, with_file = [], []
        with tempfile.TemporaryDirectory() as folder:
            restart = Path(folder) / 'maud.json'
            for _ in range(args.repeats):
                for path in (restart, restart.with_name('maud.json.arrays')):
                    path.unlink(missing_ok=True)
                plain.append(one_run(name, int(size), args.fmax, None))
                with_file.append(one_run(name, int(size), args.fmax, restart))
            kb = sum(path.stat().st_size for path in Path(folder).iterdir()) / 1e3
        without, within = (np.median([t for t, _ in runs]) for runs in (plain, with_file))
        row = (f'| {name} {size} | {len(build(name, int(size)))} | {plain[0][1]} | '
               f'{without:.3f} | {within:.3f} | {within / without:.3f} | {kb:.0f} |')
        print(row, flush=True)
        lines.append(row)
    if args.out:
        args.out.write_text('\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
