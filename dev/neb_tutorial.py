"""ASE's NEB tutorial (Au hopping between hollow sites of Al(100), EMT, three
moving images) relaxed by FIRE, BFGS and Maud: steps to fmax 0.05 eV/A and the
barrier. docs/optimizer.md quotes the output; tests/workflows/test_ase_drivers.py uses
:func:`tutorial_band` and :func:`relax_band`::

    python dev/neb_tutorial.py --seeds 0 1
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from ase.build import add_adsorbate, fcc100
from ase.calculators.emt import EMT
from ase.constraints import FixAtoms
from ase.mep import NEB
from ase.optimize import BFGS, FIRE, QuasiNewton

from ase_maud import Maud

OPTIMIZERS = {'FIRE': FIRE, 'BFGS': BFGS, 'Maud': Maud}


def tutorial_band(jitter_seed: int) -> tuple[NEB, list]:
    """The tutorial's band, its middle images' Au moved by up to 0.02 A
    (seeded) so that each seed is a fresh start; returns (band, images)."""
    slab = fcc100('Al', size=(2, 2, 3))
    add_adsorbate(slab, 'Au', 1.7, 'hollow')
    slab.center(axis=2, vacuum=4.0)
    slab.set_constraint(FixAtoms(mask=[atom.tag > 1 for atom in slab]))
    slab.calc = EMT()
    QuasiNewton(slab, logfile=None).run(fmax=0.05)
    initial = slab.copy()
    slab[-1].x += slab.get_cell()[0, 0] / 2
    QuasiNewton(slab, logfile=None).run(fmax=0.05)
    final = slab.copy()
    images = [initial] + [initial.copy() for _ in range(3)] + [final]
    for image in images:
        image.calc = EMT()
    rng = np.random.default_rng(jitter_seed)
    band = NEB(images, method='improvedtangent')
    band.interpolate()
    for image in images[1:-1]:
        image.positions[-1] += rng.uniform(-0.02, 0.02, 3)
    return band, images


def relax_band(optimizer, seed: int, **kwargs) -> tuple[bool, int, float]:
    """(converged, steps, barrier in eV) of ``optimizer`` on the band of
    ``seed``, to fmax 0.05 within 300 steps."""
    band, images = tutorial_band(seed)
    opt = optimizer(band, logfile=None, **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', UserWarning)
        converged = bool(opt.run(fmax=0.05, steps=300))
    barrier = max(image.get_potential_energy() for image in images)
    return converged, opt.nsteps, barrier - images[0].get_potential_energy()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1])
    args = parser.parse_args()
    print('| seed | optimiser | converged | steps | barrier eV |')
    print('|---|---|---|---|---|')
    for seed in args.seeds:
        for name, optimizer in OPTIMIZERS.items():
            done, steps, barrier = relax_band(optimizer, seed)
            print(f'| {seed} | {name} | {done} | {steps} | {barrier:.4f} |', flush=True)


if __name__ == '__main__':
    main()
