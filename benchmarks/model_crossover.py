"""Where the exact model stops paying: Maud with model='exact' against
model='springs' (the large-scene model) on scenes of growing size, calculator
calls and CPU seconds to an fmax. The crossover sets
``ase_maud.optimize.models.exact.EXACT_MAX_DOFS`` (the ``model='auto'`` switch);
docs/optimizer.md quotes the output.

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
        python benchmarks/model_crossover.py --out docs/dev/bench/crossover.md
"""

import argparse
import time
from pathlib import Path

from ase_maud import Maud
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.catalogue import build

SCENES = [('ring', n) for n in (50, 100, 200, 300)] + [
    ('hanging_net', n) for n in (8, 10, 12, 14)] + [
    ('random_graph', n) for n in (50, 100, 200, 300)] + [
    ('wheel', n) for n in (30, 60, 100)] + [('all_pairs', n) for n in (20, 40, 80)]


def measure(name, size, model, fmax, seed):
    """(calls, CPU seconds, converged) of one run."""
    atoms = build(name, size, seed=seed)
    calls, cpu, converged = calls_and_cpu(
        atoms, Maud(atoms, model=model, logfile=None), fmax, 3000)
    return calls, cpu, converged, len(atoms)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--out', type=Path, help='markdown table to write')
    args = parser.parse_args()
    measure('ring', 8, 'exact', args.fmax, args.seed)  # compiles or loads the kernels
    lines = ['| scene | N | free DOFs | exact calls | exact CPU s | springs calls '
             '| springs CPU s | CPU exact / springs |', '|---|---|---|---|---|---|---|---|']
    for name, size in SCENES:
        exact = measure(name, size, 'exact', args.fmax, args.seed)
        other = measure(name, size, 'springs', args.fmax, args.seed)
        atoms = build(name, size, seed=args.seed)
        dofs = int(free_dofs(atoms, atoms.calc.dim).sum())
        row = (f'| {name} | {exact[3]} | {dofs} | {exact[0]}{"" if exact[2] else " (not conv.)"} '
               f'| {exact[1]:.2f} | {other[0]}{"" if other[2] else " (not conv.)"} '
               f'| {other[1]:.2f} | {exact[1] / other[1]:.2f} |')
        print(row, flush=True)
        lines.append(row)
    if args.out:
        header = (f'Measured {time.strftime("%Y-%m-%d")}, fmax {args.fmax:g}, seed {args.seed}, '
                  'one thread: `python benchmarks/model_crossover.py`\n\n')
        args.out.write_text(header + '\n'.join(lines) + '\n')


if __name__ == '__main__':
    main()
