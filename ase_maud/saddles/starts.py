"""Starts of saddle searches: a scene (:func:`~ase_maud.scenes.catalogue.build`'s or
:data:`~ase_maud.scenes.saddle_scenes.SADDLE_SCENES`') relaxed to a minimum and
moved along its lowest Hessian mode (:func:`saddle_start`), or any atoms moved so
(:func:`displaced_minimum`).

The saddle benchmark (``benchmarks/saddles_vs_sella.py``) starts its searches
here, as do the tests of ``Maud(target='saddle')``.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms
from scipy.spatial import cKDTree

from ase_maud.analysis.stationary import classify
from ase_maud.counting import fresh_copy
from ase_maud.optimize.maud import Maud
from ase_maud.physics.dofs import keep_on_plane
from ase_maud.scenes.catalogue import build
from ase_maud.scenes.saddle_scenes import SADDLE_SCENES

__all__ = ['DEGENERATE_RTOL', 'DISPLACEMENTS', 'SHIFT', 'displaced_minimum', 'saddle_start']

#: How far ``up``, ``down`` and ``random`` move a minimum: this fraction of the
#: mean nearest-neighbour distance.
SHIFT = 0.1
#: The named displacements: along the lowest mode either way, or along a seeded
#: random combination of the modes.
DISPLACEMENTS = ('up', 'down', 'random')
#: Eigenvalues above the lowest by less than this fraction of the largest
#: eigenvalue's size are the lowest too: a degenerate lowest eigenvalue
#: (:func:`displaced_minimum`).
DEGENERATE_RTOL = 1e-6


def displaced_minimum(atoms: Atoms, seed: int, amp: float | str,
                      label: str = 'the scene') -> Atoms:
    """``atoms`` (a 2D scene's z held by :func:`keep_on_plane`, in place) as they are if
    ``amp`` is 0; else relaxed with Maud to fmax 1e-9 (a ValueError naming ``label`` if
    that is not a minimum, checked with :func:`~ase_maud.analysis.stationary.classify`)
    and a fresh copy moved along its lowest mode so that the point that moves most moves
    ``amp`` (units of ``a``), or by the named displacement (:data:`DISPLACEMENTS`,
    :data:`SHIFT`); ``seed`` seeds the random one. Where the lowest eigenvalue is
    degenerate (within :data:`DEGENERATE_RTOL`; the symmetric minima of a few points),
    the mode is a random vector seeded by ``seed`` projected on its eigenspace: the
    eigensolver's own basis of that space differs from one LAPACK build to another."""
    if atoms.calc.parameters['dim'] == 2:
        keep_on_plane(atoms)
    if amp in (0, '0'):
        return atoms
    Maud(atoms, logfile=None).run(fmax=1e-9, steps=5000)
    point = classify(atoms)
    if point.verdict != 'minimum':
        raise ValueError(f'{label} relaxed to a {point.verdict}, '
                         'not a minimum: no lowest mode to leave it along')
    values = point.eigenvalues
    lowest = np.flatnonzero(values - values[0] <= DEGENERATE_RTOL * abs(values).max())
    mode = point.modes[0]
    if len(lowest) > 1:   # a seeded vector's projection: the same in any basis
        space = point.modes[lowest]
        seeded = np.random.default_rng(seed).normal(size=space.shape[1:])
        mode = np.einsum('k,kij->ij', np.einsum('kij,ij->k', space, seeded), space)
    if amp in DISPLACEMENTS:
        if amp == 'random':
            weights = np.random.default_rng(seed).normal(size=len(point.modes))
            mode = np.einsum('k,kij->ij', weights, point.modes)
        spacing = np.mean(cKDTree(atoms.positions).query(atoms.positions, k=2)[0][:, 1])
        amp = SHIFT * spacing * (-1 if amp == 'down' else 1)
    start = fresh_copy(atoms)
    start.positions += float(amp) * mode / np.linalg.norm(mode, axis=1).max()
    return start


def saddle_start(scene: str, size: int, seed: int, amp: float | str) -> Atoms:
    """The start ``scene:size:amp``: the scene of ``size`` built with ``seed`` (a
    :data:`~ase_maud.scenes.saddle_scenes.SADDLE_SCENES` name or a catalogue one), then
    :func:`displaced_minimum` by ``amp``, its random displacement seeded by ``seed``."""
    atoms = SADDLE_SCENES[scene](size, seed) if scene in SADDLE_SCENES else build(
        scene, size, seed=seed)
    return displaced_minimum(atoms, seed, amp, f'{scene} {size} seed {seed}')
