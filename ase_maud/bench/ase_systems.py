"""ASE's usual systems for a calculator with no stiffness (issue 32): the
starts ``benchmarks/ase_systems.py`` compares optimisers from, each made from a
seed.

A :class:`Start` is what an optimiser relaxes (Atoms, a cell filter or a
band of images), with the atoms whose calculators the benchmark counts."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from ase import Atoms
from ase.build import add_adsorbate, bulk, fcc100, fcc111
from ase.calculators.emt import EMT
from ase.calculators.lj import LennardJones
from ase.cluster import Icosahedron
from ase.constraints import FixAtoms
from ase.filters import FrechetCellFilter
from ase.mep import NEB
from ase.optimize import BFGS


@dataclass
class Start:
    """What an optimiser is given (``target``: Atoms, a Filter or a NEB) and
    the ``images`` (Atoms) whose calculators do the work."""

    target: Any
    images: list[Atoms]

    @property
    def band(self) -> bool:
        """Whether the target is a band of images (no energy to minimise)."""
        return isinstance(self.target, NEB)

    def energy(self) -> float:
        """The final energy (eV, epsilon for LJ): of the atoms, or the highest
        image of a band (its barrier top)."""
        return max(image.get_potential_energy() for image in self.images)


def lj_cluster(n: int, seed: int) -> Atoms:
    """``n`` LJ atoms at random in a sphere of density 0.5 (sigma 1), no two
    closer than 0.8."""
    rng = np.random.default_rng(seed)
    radius = (3 * n / (4 * np.pi * 0.5)) ** (1 / 3)
    points: list[np.ndarray] = []
    while len(points) < n:
        p = rng.uniform(-radius, radius, 3)
        if np.linalg.norm(p) <= radius and all(np.linalg.norm(p - q) > 0.8 for q in points):
            points.append(p)
    atoms = Atoms(f'Ar{n}', positions=points)
    atoms.calc = LennardJones(rc=10.0)
    return atoms


def lj7(seed: int) -> Atoms:
    """ASE's BasinHopping test start (ase/test/test_basin.py): 7 LJ atoms
    (ASE's defaults: sigma 1, cut-off 3) uniform in the cube of half-side
    ``7**(1/3)``, drawn by ``RandomState(42 + seed)``."""
    n = 7
    half = n ** (1 / 3)
    atoms = Atoms(f'He{n}', positions=np.random.RandomState(42 + seed).uniform(
        -half, half, (n, 3)))
    atoms.calc = LennardJones()
    return atoms


def lj_molecule(seed: int) -> Atoms:
    """The O4 molecule of ASE's NEB test (ase/test/neb/test_neb_tr.py, its
    initial state) with ASE's default LJ (sigma 1, cut-off 3), rattled by
    0.05."""
    atoms = Atoms('O4', positions=[(1.94366484, 2.24788196, 2.32204726),
                                   (3.05353823, 2.08091038, 2.30712548),
                                   (2.63770601, 3.05694348, 2.67368242),
                                   (2.50579418, 2.12540646, 3.28585811)],
                  cell=(5, 5, 5))
    atoms.rattle(stdev=0.05, seed=seed)
    atoms.calc = LennardJones()
    return atoms


def pt13(seed: int) -> Atoms:
    """The Pt13 cluster (EMT) of ASE's line-search test
    (ase/test/test_linesearch_maxstep.py), rattled by 0.05 A."""
    positions = [[5.8324672234339969, 8.5510800490537271, 5.686535793302002],
                 [7.3587688835494625, 5.646353802990923, 6.8378173997818958],
                 [7.9908510609316235, 5.4456005797117335, 4.5249260246251213],
                 [9.7103024117445145, 6.4768915365291466, 4.6502022197421278],
                 [9.5232482249292509, 8.7417754382952051, 4.6747936030744448],
                 [8.2738330473112036, 7.640248516254645, 6.1624124370797215],
                 [7.4198265919217921, 9.2882534361810016, 4.3654132356242874],
                 [6.8506783463494623, 9.2004422130272605, 8.611538688631887],
                 [5.9081131977596133, 5.6951755645279949, 5.4134092632199602],
                 [9.356736354387575, 9.2718534012646359, 8.491942486888524],
                 [9.0390271264592403, 9.5752757925665453, 6.4771649275571779],
                 [7.0554382804264533, 7.0016335250680779, 8.418151938177477],
                 [9.4855926945401272, 5.5650406772147694, 6.8445655410690591]]
    atoms = Atoms('Pt13', positions=positions, cell=[15] * 3)
    atoms.rattle(stdev=0.05, seed=seed)
    atoms.calc = EMT()
    return atoms


def au13(seed: int) -> Atoms:
    """An EMT Au13 icosahedron rattled by 0.1 A."""
    atoms = Icosahedron('Au', 2)
    atoms.rattle(stdev=0.1, seed=seed)
    atoms.calc = EMT()
    return atoms


def bulk_au32(seed: int) -> Atoms:
    """Bulk Au32 (EMT), rattled by 0.1 A."""
    atoms = bulk('Au', cubic=True) * (2, 2, 2)
    atoms.rattle(stdev=0.1, seed=seed)
    atoms.calc = EMT()
    return atoms


def au8_cell(seed: int) -> Start:
    """Issue 32's cell-filter case: ``bulk('Au') * 2`` (EMT) rattled by
    0.005 A under ``FrechetCellFilter(exp_cell_factor=1)``."""
    atoms = bulk('Au') * 2
    atoms.rattle(stdev=0.005, seed=seed)
    atoms.calc = EMT()
    return Start(FrechetCellFilter(atoms, exp_cell_factor=1.0), [atoms])


def o_au111(seed: int) -> Atoms:
    """O on a 2x2x3 Au(111) slab (EMT), its bottom layer fixed, rattled by 0.05 A."""
    slab = fcc111('Au', size=(2, 2, 3), vacuum=6.0)
    add_adsorbate(slab, 'O', 1.5, 'fcc')
    slab.set_constraint(FixAtoms(mask=[atom.tag == 3 for atom in slab]))
    slab.rattle(stdev=0.05, seed=seed)
    slab.calc = EMT()
    return slab


def al_au_neb(seed: int) -> Start:
    """ASE's NEB test band (ase/test/neb/test_neb.py): Au hopping between
    hollow sites of Al(100) 2x2x3 (EMT, lower two layers fixed), three
    images between end points relaxed by BFGS to fmax 0.01 (not counted),
    ``improvedtangent``, interpolated and the inner images rattled by
    0.02 A."""
    slab = fcc100('Al', size=(2, 2, 3))
    add_adsorbate(slab, 'Au', 1.7, 'hollow')
    slab.center(axis=2, vacuum=4.0)
    slab.set_constraint(FixAtoms(mask=slab.get_tags() > 1))
    initial, final = slab.copy(), slab.copy()
    final[-1].x += final.get_cell()[0, 0] / 2
    for end in (initial, final):
        end.calc = EMT()
        with BFGS(end, logfile=None) as opt:
            opt.run(fmax=0.01)
    inner = [initial.copy() for _ in range(3)]
    band = NEB([initial, *inner, final], method='improvedtangent')
    band.interpolate()
    for k, image in enumerate(inner):
        image.rattle(stdev=0.02, seed=100 * seed + k)
        image.calc = EMT()
    return Start(band, inner)


def _atoms(make):
    def start(seed: int) -> Start:
        atoms = make(seed)
        return Start(atoms, [atoms])
    return start


#: Each system by name, a function of the seed.
SYSTEMS = {'LJ7': _atoms(lj7), 'LJ13': _atoms(lambda s: lj_cluster(13, s)),
           'LJ38': _atoms(lambda s: lj_cluster(38, s)), 'LJ O4': _atoms(lj_molecule),
           'Pt13': _atoms(pt13), 'Au13': _atoms(au13), 'Au32': _atoms(bulk_au32),
           'Au8 cell': au8_cell, 'O/Au(111)': _atoms(o_au111), 'Al/Au NEB': al_au_neb}
