"""``classify`` above its dense size: the lowest eigenpairs of one dense Hessian
(``method='lowest'``) against LOBPCG on Hessian-vector products (``'iterative'``,
what ``'auto'`` takes above ``DENSE_MAX_DOFS``), on minima of scenes drawn from the
seeded families (:mod:`ase_maud.scenes.families`). Per scene and path: the verdict,
the lowest eigenvalue, the products or Hessians counted, CPU seconds
(``ase_maud.counting.cpu_seconds``: run with one thread) and the process's peak memory.
Printed a row each, and written to ``--out`` (a CSV; an existing file is never
replaced)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/classify_paths.py --seed 2 --sizes 1000 1500 --out classify.csv
"""

from __future__ import annotations

import argparse
import csv
import sys
import warnings
from pathlib import Path

from ase_maud import Maud, classify
from ase_maud.counting import Work, cpu_seconds
from ase_maud.scenes.families import FAMILIES


def rows(family: str, seed: int, sizes: tuple[int, int]) -> list[dict]:
    """Both paths on the minimum of ``family``'s scene of ``seed``."""
    atoms = FAMILIES[family](seed, sizes)
    Maud(atoms, logfile=None).run(fmax=1e-8, steps=5000)
    out = []
    for method in ('lowest', 'iterative'):
        work, start = Work(), cpu_seconds()
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            point = classify(atoms, method=method, work=work)
        out.append({'family': family, 'seed': seed, 'natoms': len(atoms), 'method': method,
                    'verdict': point.verdict, 'lowest': f'{point.eigenvalues[0]:.6g}',
                    'hvp_vectors': work.hvp_vectors, 'hessians': work.hessians,
                    'cpu_s': round(cpu_seconds() - start, 3)})
        print(' '.join(f'{k}={v}' for k, v in out[-1].items()), flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--families', nargs='+', default=['sagging_net', 'knn_cluster',
                                                          'random_tree'], choices=FAMILIES)
    parser.add_argument('--seed', type=int, default=2)
    parser.add_argument('--sizes', type=int, nargs=2, default=[1000, 1500])
    parser.add_argument('--out', type=Path, required=True)
    args = parser.parse_args()
    if args.out.exists():
        sys.exit(f'{args.out} exists: give an --out that does not')
    table = [row for family in args.families
             for row in rows(family, args.seed, tuple(args.sizes))]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open('x', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=list(table[0]))
        writer.writeheader()
        writer.writerows(table)


if __name__ == '__main__':
    main()
