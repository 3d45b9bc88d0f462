"""A band of images relaxed as a string preconditioned by each image's stiffness model.

The simplified string method (E, Ren and Vanden-Eijnden, J. Chem. Phys. 126, 164103,
2007) with a climbing image (Ren and Vanden-Eijnden, J. Chem. Phys. 138, 134105, 2013),
preconditioned as in Makri, Ortner and Kermode (J. Chem. Phys. 150, 094109, 2019). Each
moving image ``i`` steps by

    d_i = P_i^-1 f_i - m c_i t_i,    c_i = <P_i^-1 f_i, P_i t_i> / <t_i, P_i t_i>,

``f_i`` its forces, ``t_i`` the band's tangent there, ``P_i`` the image's global stiffness
model (:class:`~ase_maud.optimize.models.global_model.GlobalModel`, the model of
:class:`~ase_maud.optimize.precon.MaudPrecon`: springs and the repulsion's nodal blocks,
force per length; rebuilt where the image has moved by half its neighbour distance, its
nodal blocks asked for in the same calculator call as the energy and forces), ``m`` 1
(the step across the path: the model's Newton step with the move along the path taken
out in ``P_i``'s metric) or 2 for the climbing image (the
highest, which then climbs along the path and descends across it). No point moves by more
than :data:`MAX_MOVE` ``a`` in a step (the image's step is scaled down). After each step
the images are spaced evenly by arc length along the cubic spline through the band
(SciPy's ``CubicSpline``; the climbing image stays where it is, each side spaced on its
own), so a string needs no springs between its images.

The moving images are evaluated at once, each on a thread of its own, as many at a time as
numba has threads (``numba.get_num_threads()``), each image's direct sum on its thread
alone: a band's steps are the same whatever numba's thread count, and the work between
calls (each image's factorisation, its neighbour search) runs on every core. With numba
on one thread the images are evaluated in turn on the caller's thread (a thread switch an
image cost about an eighth of a 500-point band's CPU). The models start afresh at each
:meth:`PreconditionedString.relax`.

A band is relaxed when every moving image's residual, ``|f_i - m c_i P_i t_i|`` (largest
component, force units), is below a target: zero exactly where ``d_i`` is, the force across
the path in ``P_i``'s metric (Makri et al., eq. 11). The metric shapes the path but not its
stationary points: a climbing image at rest has zero forces.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numba
import numpy as np
from ase import Atoms
from scipy.interpolate import CubicSpline

from ase_maud.optimize.models.global_model import GlobalModel

#: The largest move of a point in one step of an image, in units of the scene's ``a``.
MAX_MOVE = 0.5


class PreconditionedString:
    """The string through ``band`` (Atoms with MaudCalculators, the two ends fixed),
    moved in place by :meth:`relax` (module docstring). ``steps``: the steps taken so
    far; ``residual``: the largest residual of the last step (force units)."""

    def __init__(self, band: list[Atoms]):
        if len(band) < 3:
            raise ValueError(f'a string needs at least one moving image between its ends, '
                             f'got a band of {len(band)}')
        self.band = band
        self.models = [GlobalModel() for _ in band[1:-1]]
        self.max_move = MAX_MOVE * band[0].calc.potential.a
        self.steps = 0
        self.residual = float('inf')

    def relax(self, target: float, steps: int, climb: bool) -> bool:
        """Step until every residual is below ``target`` (force units) or ``steps`` steps
        were taken, with a climbing image if ``climb``; whether it got there. The images
        are left at the last positions evaluated."""
        positions = np.array([image.positions for image in self.band])
        images = self.band[1:-1]
        lanes = _Lanes(len(images))
        try:
            for taken in range(steps + 1):
                tangents = _tangents(positions)
                evaluated = lanes.each(_evaluate, images, self.models, tangents[1:-1])
                top = 1 + int(np.argmax([energy for energy, *_ in evaluated])) if climb else None
                moves, self.residual = [], 0.0
                for i, (_, forces, step, towards) in enumerate(evaluated, 1):
                    along = ((2 if i == top else 1) * np.vdot(step, towards)
                             / np.vdot(tangents[i], towards))
                    self.residual = max(self.residual,
                                        float(np.abs(forces - along * towards).max()))
                    moves.append(step - along * tangents[i])
                if self.residual < target:
                    return True
                if taken == steps:
                    return False
                for i, move in enumerate(moves, 1):
                    longest = float(np.linalg.norm(move, axis=1).max())
                    positions[i] += (min(1.0, self.max_move / longest) if longest > 0
                                     else 0.0) * move
                positions = _spaced(positions, top)
                for image, moved in zip(images, positions[1:-1], strict=True):
                    image.positions = moved
                self.steps += 1
            return False
        finally:
            lanes.each(self._renew, range(len(images)))
            lanes.shutdown()

    def _renew(self, k: int) -> None:
        """A new model for moving image ``k``, the old one (and its factorisation) let
        go on this thread: SciPy's SuperLU frees its memory only on the thread that
        allocated it (a factorisation freed on another is never freed)."""
        self.models[k] = GlobalModel()


class _Lanes:
    """Where the ``count`` moving images are evaluated: with numba on more than one
    thread, each on a thread of its own (numba on one thread there), at most numba's
    thread count of them at once; with numba on one, in turn on the caller's thread
    (handing each to a thread of its own would only add a thread switch an image)."""

    def __init__(self, count: int):
        threads = numba.get_num_threads()
        self.threads = ([ThreadPoolExecutor(1, initializer=numba.set_num_threads, initargs=(1,))
                         for _ in range(count)] if threads > 1 else [])
        self.running = threading.BoundedSemaphore(min(threads, count)) if self.threads else None

    def each(self, function: Callable[..., Any], *columns: Iterable[Any]) -> list[Any]:
        """``function`` of each moving image's row of ``columns``, in the images' order."""
        rows = zip(*columns, strict=True)
        if not self.threads:
            return [function(*row) for row in rows]

        def task(*row):
            with self.running:
                return function(*row)
        futures = [thread.submit(task, *row)
                   for thread, row in zip(self.threads, rows, strict=True)]
        return [future.result() for future in futures]

    def shutdown(self) -> None:
        for thread in self.threads:
            thread.shutdown()


def _evaluate(image: Atoms, model: GlobalModel,
              tangent: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """What the step of ``image`` needs: its energy, forces ``f``, ``P^-1 f`` and
    ``P t`` (``P`` its ``model``'s, ``t`` the band's unit ``tangent`` there)."""
    energy = _energy(image, model)
    forces = image.get_forces()
    solver = model.at(image)
    return energy, forces, solver.solve(forces), solver.dot(tangent)


def _energy(image: Atoms, model: GlobalModel) -> float:
    """The energy of ``image``, its forces and, where ``model`` will rebuild there, its
    nodal blocks computed in the same calculator call."""
    needed = model.needs(image)
    if needed is not None:
        image.calc.get_property(needed, image)
    return image.get_potential_energy()


def _spline(positions: np.ndarray) -> tuple[np.ndarray, CubicSpline]:
    """The cumulative arc length at each image (the polyline's, length units) and the
    cubic spline through the images by it."""
    flat = positions.reshape(len(positions), -1)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(flat, axis=0), axis=1))])
    return arc, CubicSpline(arc, positions, axis=0)


def _tangents(positions: np.ndarray) -> np.ndarray:
    """The band's unit tangent at each image (the spline's derivative), images x points x 3."""
    arc, spline = _spline(positions)
    tangents = spline(arc, 1)
    norms = np.linalg.norm(tangents.reshape(len(positions), -1), axis=1)
    return tangents / norms[:, None, None]


def _spaced(positions: np.ndarray, keep: int | None) -> np.ndarray:
    """The images moved along the spline through them to even arc length, the ends and
    image ``keep`` (if given) kept, each side of it spaced on its own."""
    arc, spline = _spline(positions)
    last = len(positions) - 1
    marks = [0, last] if keep is None else [0, keep, last]
    spaced = positions.copy()
    for start, stop in itertools.pairwise(marks):
        spaced[start + 1:stop] = spline(np.linspace(arc[start], arc[stop], stop - start + 1)[1:-1])
    return spaced
