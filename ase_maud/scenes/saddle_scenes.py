"""Scenes for saddle searches, beside :func:`~ase_maud.scenes.catalogue.build`'s:
a ring with chords, nets with their corners or their whole rim fixed (a dome)
and a tube held at both ends. Each is built by ``name(size, seed)``, seeded;
:data:`SADDLE_SCENES` holds them by name.

The saddle benchmarks start from them (``benchmarks/saddles_vs_sella.py``,
``benchmarks/saddle_search.py``, ``benchmarks/snap_through.py``), as do the
tests of :mod:`ase_maud.saddles`: their minima have collective saddles
nearby (a chord ring's buckling, a dome's snap-through).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.scenes.catalogue import build

__all__ = ['SADDLE_SCENES', 'chords', 'corners', 'rim', 'tube']


def chords(size: int, seed: int) -> Atoms:
    """``ring`` with a chord from each point to the one a third of the way round."""
    atoms = build('ring', size, seed=seed)
    n = len(atoms)
    chords = np.column_stack([np.arange(n), (np.arange(n) + n // 3) % n])
    atoms.calc = type(atoms.calc)(**{**atoms.calc.parameters, 'springs': np.vstack(
        [atoms.calc.parameters['springs'], chords])})
    return atoms


def corners(size: int, seed: int) -> Atoms:
    """``net3d`` with its four corners fixed."""
    atoms = build('net3d', size, seed=seed)
    side = int(round(np.sqrt(len(atoms))))
    atoms.set_constraint(FixAtoms([0, side - 1, side * (side - 1), side * side - 1]))
    return atoms


def rim(size: int, seed: int) -> Atoms:
    """``net3d`` with its whole rim fixed: the repulsion buckles it into a dome."""
    atoms = build('net3d', size, seed=seed)
    side = int(round(np.sqrt(len(atoms))))
    edge = np.zeros((side, side), dtype=bool)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    atoms.set_constraint(FixAtoms(np.flatnonzero(edge.ravel())))
    return atoms


def tube(size: int, seed: int) -> Atoms:
    """A tube of ``size`` rings of ``size`` points (spacing a round and along), springs
    round each ring and between rings, both end rings fixed; every free coordinate moved
    by up to 0.2 a (seeded)."""
    rng = np.random.default_rng(seed)
    phi = 2 * np.pi * np.arange(size) / size
    radius = size / (2 * np.pi)
    positions = np.concatenate([np.column_stack([radius * np.cos(phi), radius * np.sin(phi),
                                                 np.full(size, k)]) for k in range(size)])
    index = np.arange(size * size).reshape(size, size)
    springs = np.concatenate([
        np.column_stack([index.ravel(), np.roll(index, -1, axis=1).ravel()]),
        np.column_stack([index[:-1].ravel(), index[1:].ravel()])])
    fixed = np.concatenate([index[0], index[-1]])
    free = np.setdiff1d(np.arange(len(positions)), fixed)
    positions[free] += rng.uniform(-0.2, 0.2, (len(free), 3))
    atoms = Atoms(positions=positions, pbc=False)
    atoms.calc = MaudCalculator(springs)
    atoms.set_constraint(FixAtoms(fixed))
    return atoms


#: The scenes of this module by name: ``name(size, seed) -> Atoms``.
SADDLE_SCENES: dict[str, Callable[[int, int], Atoms]] = {
    'chords': chords, 'corners': corners, 'rim': rim, 'tube': tube}
