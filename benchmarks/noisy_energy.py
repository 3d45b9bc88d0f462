"""Calls of Maud on scenes whose energies carry noise, to compare two versions.

Each scene of :data:`SCENES`, seeds 0-2, relaxed with ``Maud(atoms)`` (the
default model) to ``--fmax`` on the :class:`ase_maud.bench.doubles.NoisyEnergy` calculator
(the exact direct sum, its energy off by a seeded uniform noise of relative
size ``noise`` that it declares as its error), for each ``--noise``: a
markdown table of the steps to converge per seed (or the error that stopped
the run). It uses the public API and that double only, so the same
script measures an older checkout (``PYTHONPATH=OLD_CHECKOUT``; one older than
``ase_maud/bench/doubles.py`` needs that file copied in)::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/noisy_energy.py --noise 0 1e-3 1e-2
"""

from __future__ import annotations

import argparse

from ase_maud import Maud
from ase_maud.bench.doubles import NoisyEnergy
from ase_maud.scenes.catalogue import build

SCENES = [('hanging_net', 20), ('hub_net', 48), ('disc', 400), ('neighbour_graph', 300),
          ('tree', 200)]
SEEDS = (0, 1, 2)


def steps(scene: str, size: int, seed: int, noise: float, fmax: float,
          most: int) -> str:
    """The steps ``Maud`` takes to ``fmax`` on the noisy scene, or why it stopped."""
    atoms = build(scene, size, seed=seed)
    atoms.calc = NoisyEnergy(noise, seed, **atoms.calc.parameters)
    try:
        with Maud(atoms, logfile=None) as opt:
            done = opt.run(fmax=fmax, steps=most)
    except Exception as error:   # recorded, so that both versions are compared
        return type(error).__name__
    return str(opt.nsteps) if done else f'>{most}'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--noise', type=float, nargs='+', default=[0.0, 1e-3, 1e-2],
                        help="the energies' relative noise (declared as their error)")
    parser.add_argument('--fmax', type=float, default=1e-5)
    parser.add_argument('--steps', type=int, default=1000)
    args = parser.parse_args()
    print('| scene | size | noise | ' + ' | '.join(f'seed {s}' for s in SEEDS) + ' |')
    print('|---|---|---|' + '---|' * len(SEEDS))
    for scene, size in SCENES:
        for noise in args.noise:
            cells = [steps(scene, size, seed, noise, args.fmax, args.steps)
                     for seed in SEEDS]
            print(f'| {scene} | {size} | {noise:g} | ' + ' | '.join(cells) + ' |',
                  flush=True)


if __name__ == '__main__':
    main()
