"""Relax a large net with Maud and classify the result without a dense Hessian.

The default is the 100 x 100 ``net2d`` scene (10^4 points, boundary fixed):
Maud relaxes it, then ``classify(method='iterative')`` finds the lowest
eigenvalues by LOBPCG on Hessian-vector products. Times are printed with the
thread count. Run:

    NUMBA_NUM_THREADS=2 python examples/classify_large_net.py --size 100
"""

import argparse
import time

import numba

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.scenes.catalogue import build


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--scene', default='net2d')
    parser.add_argument('--size', type=int, default=100)
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--k', type=int, default=6)
    args = parser.parse_args()
    atoms = build(args.scene, args.size, seed=0)
    print(f'{args.scene} {args.size}: {len(atoms)} points, '
          f'{numba.get_num_threads()} numba threads')
    start = time.perf_counter()
    with Maud(atoms, logfile=None) as opt:
        converged = opt.run(fmax=args.fmax, steps=5000)
    relax_s = time.perf_counter() - start
    print(f'relaxed: converged={converged} in {opt.nsteps} steps, '
          f'{relax_s:.1f} s, energy {atoms.get_potential_energy():.10g}')
    start = time.perf_counter()
    point = classify(atoms, method='iterative', k=args.k,
                     ftol=10 * args.fmax)
    classify_s = time.perf_counter() - start
    print(f'classified: {point.verdict} (index {point.index}) in '
          f'{classify_s:.1f} s; lowest eigenvalues '
          + ' '.join(f'{e:.3e}' for e in point.eigenvalues))


if __name__ == '__main__':
    main()
