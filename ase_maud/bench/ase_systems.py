"""ASE's usual systems for a calculator with no stiffness (issue 32): the
starts ``tools/ase_systems.py`` compares optimisers from, each made from a
seed."""

from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.build import add_adsorbate, bulk, fcc111
from ase.calculators.emt import EMT
from ase.calculators.lj import LennardJones
from ase.cluster import Icosahedron
from ase.constraints import FixAtoms


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


def o_au111(seed: int) -> Atoms:
    """O on a 2x2x3 Au(111) slab (EMT), its bottom layer fixed, rattled by 0.05 A."""
    slab = fcc111('Au', size=(2, 2, 3), vacuum=6.0)
    add_adsorbate(slab, 'O', 1.5, 'fcc')
    slab.set_constraint(FixAtoms(mask=[atom.tag == 3 for atom in slab]))
    slab.rattle(stdev=0.05, seed=seed)
    slab.calc = EMT()
    return slab


#: Each system by name, a function of the seed.
SYSTEMS = {'LJ13': lambda s: lj_cluster(13, s), 'LJ38': lambda s: lj_cluster(38, s),
           'Au13': au13, 'Au32': bulk_au32, 'O/Au(111)': o_au111}
