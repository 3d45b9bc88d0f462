"""The near-field model (``model='near'``): the springs model's ``P`` plus the
repulsion's pair blocks of near pairs, solved matrix-free by truncated CG
preconditioned by the springs model's own factor.

Where the repulsion, not the springs, sets the shape (free neighbour graphs,
dense meshes, nets with a hub), the springs model's ``P = Q L + diag(s)`` is a
weak model of the Hessian: a spring under tension across its repulsion is
soft sideways (the repulsion's pair block holds ``-I / L**3`` across the
pair), which ``Q L`` takes as stiff. This model adds, signed as they are, the
repulsion's pair blocks ``Q B(r_i - r_j)`` (:func:`ase_maud.physics.pair_law.repulsion_block`,
``r`` in units of ``a``) of the near pairs::

    P = P_springs + R,    R = sum_p (e_i - e_j)(e_i - e_j)^T (x) Q B(r_i - r_j)

over the pairs nearer than ``cutoff`` times the median nearest-neighbour
distance and the springs with an end that has at most
:data:`SPRUNG_PER_POINT` springs (:func:`near_pairs`, :func:`sparse_springs`):
the Hessian less the far field's couplings. ``P`` is indefinite far from a
minimum, so it is not factorised: the move solves ``P d = f`` by conjugate
gradients preconditioned by ``P_springs^-1`` (the springs model's factor,
kept for the run), to the relative residual :data:`NEAR_RTOL` in at most
:data:`NEAR_MAXITER` products, stopped where a direction of negative
curvature appears (the iterate so far; at the first the springs model's
move). The move is projected off the rigid motions (``P``, short of the far
field, is not invariant under rotations).

A product costs no ``P_springs`` product: with ``z = P_springs^-1 r`` (exact
for a factorised ``P_springs``; to :data:`~ase_maud.optimize.models.springs.SPRINGS_RTOL`
from 2e5 points, where it is multigrid), ``P z = r + R z``, and a search
direction's product follows by the CG recursion; so a product is one sparse
product with ``R`` (O(pairs): a few a point where the spacing is even, and
at most :data:`SPRUNG_PER_POINT` springs a point) whatever the spring graph, a
cluster whose every pair is sprung included; the pairs are found in O(N log N)
a step (a k-d tree), the springs kept once per run.
Products are counted in the model's ``work.near_products`` (they are not
calculator calls nor Hessian-vector products, whose cost is a force call's).

The model learns nothing in a run (the pairs are found again at every step,
from the positions alone), so a run stopped and resumed repeats the
uninterrupted one bit for bit. Its step rule is the springs model's
(:data:`ase_maud.optimize.step_rules.STEP_DEFAULTS`, by class). Only ``target='minimum'``.
docs/performance.md (and the notebook, docs/dev/benchmarks.md) has where it pays.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from scipy.spatial import cKDTree

from ase_maud.counting import Work
from ase_maud.optimize.models.base import Solver, held_at_zero
from ase_maud.optimize.models.springs import SpringsModel
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import free_dofs, rigid_body_modes
from ase_maud.physics.neighbours import NearestDistances

#: Pairs nearer than this many median nearest-neighbour distances get their
#: repulsion block (about 2 a point in a free graph; the spectra of
#: docs/dev/benchmarks.md, "Repulsion-dominated scenes").
NEAR_CUTOFF = 1.5
#: ... and the springs with an end that has at most this many springs:
#: every spring of a graph of lower degree (nets, meshes, free graphs, a
#: hub's spokes), at most 12 N of a denser one (a cluster whose every pair
#: is sprung keeps only its near pairs).
SPRUNG_PER_POINT = 12
#: Relative residual of the truncated CG, and its most ``P`` products a step.
NEAR_RTOL, NEAR_MAXITER = 0.5, 50


def near_pairs(x: np.ndarray, springs: np.ndarray,
               cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """The pairs ``(i, j)`` (two index arrays, ``i < j``, each pair once): the
    ``springs`` (K, 2) and the pairs of the points ``x`` (N, dim) nearer than
    ``cutoff`` times their median nearest-neighbour distance."""
    n = len(x)
    springs = np.sort(np.asarray(springs, dtype=np.int64).reshape(-1, 2), axis=1)
    if n < 2:
        return springs[:, 0], springs[:, 1]
    tree = cKDTree(x)
    spacing = float(np.median(tree.query(x, k=2)[0][:, 1]))
    near = tree.query_pairs(cutoff * spacing, output_type='ndarray').astype(np.int64)
    if len(springs) and len(near):
        sprung = np.sort(springs[:, 0] * n + springs[:, 1])
        keys = near[:, 0] * n + near[:, 1]   # query_pairs gives i < j
        at = np.minimum(np.searchsorted(sprung, keys), len(sprung) - 1)
        near = near[sprung[at] != keys]
    pairs = np.concatenate([springs, near.reshape(-1, 2)])
    return pairs[:, 0], pairs[:, 1]


def sparse_springs(springs: np.ndarray, n: int, per_point: int | None) -> np.ndarray:
    """The ``springs`` (K, 2) of ``n`` points that have an end with at most
    ``per_point`` springs (None: every spring): at most ``per_point n``, and
    every one of a spring graph of that degree (a hub's spokes too, by their
    other end)."""
    springs = np.asarray(springs, dtype=np.int64).reshape(-1, 2)
    if per_point is None or not len(springs):
        return springs
    degree = np.bincount(springs.ravel(), minlength=n)
    return springs[degree[springs].min(axis=1) <= per_point]


class NearModel(SpringsModel):
    """``P = P_springs + R`` solved by truncated CG; see the module
    docstring. ``cutoff`` (a multiple of the median nearest-neighbour
    distance) and ``per_point`` (the most springs of a spring's sparser
    end; None: every spring) choose the pairs (:func:`near_pairs`,
    :func:`sparse_springs`)."""

    name = 'near'

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 nearest: NearestDistances | None = None, cutoff: float = NEAR_CUTOFF,
                 per_point: int | None = SPRUNG_PER_POINT):
        super().__init__(target, floor, nearest)
        if self.target != 'minimum':
            raise ValueError(f"model='near' seeks a minimum only (its CG stops on negative "
                             f"curvature), got target={target!r}; use model='springs'")
        if not (cutoff >= 0 and (per_point is None or per_point >= 0)):
            raise ValueError(f'cutoff and per_point must be >= 0 (per_point may be None), '
                             f'got {cutoff!r} and {per_point!r}')
        self.cutoff = float(cutoff)
        self.per_point = None if per_point is None else int(per_point)
        self._sprung: tuple[Any, int, np.ndarray] | None = None

    def todict(self) -> dict[str, Any]:
        return {**super().todict(), 'cutoff': self.cutoff, 'per_point': self.per_point}

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        springs = super().at(atoms, learnt)
        potential = atoms.calc.potential
        dim = potential.dim
        free = free_dofs(atoms, dim)
        i, j = self.pairs(atoms)
        x = potential.reduced(atoms.positions)[:, :dim]
        blocks = potential.Q * physics.repulsion_block(x[i] - x[j]).reshape(-1, dim, dim)
        return NearSolver(springs, pair_incidence(i, j, len(atoms)), blocks, free,
                          rigid_body_modes(atoms.positions, free, dim), self.work)

    def pairs(self, atoms: Atoms) -> tuple[np.ndarray, np.ndarray]:
        """The pairs ``(i, j)`` whose blocks ``R`` holds at ``atoms``'
        positions (:func:`near_pairs`)."""
        potential, n = atoms.calc.potential, len(atoms)
        kept = self._sprung
        if kept is None or kept[0] is not potential or kept[1] != n:
            self._sprung = kept = potential, n, sparse_springs(potential.springs, n,
                                                                self.per_point)
        x = potential.reduced(atoms.positions)[:, :potential.dim]
        return near_pairs(x, kept[2], self.cutoff)


def pair_incidence(i: np.ndarray, j: np.ndarray, n: int) -> sp.csr_matrix:
    """The incidence matrix (P, n) of the pairs ``(i, j)``: row ``p`` is
    ``e_i - e_j``, so that ``R = D^T blockdiag(B) D`` (built in O(P), no sort)."""
    indices = np.column_stack([i, j]).ravel()
    data = np.tile([1.0, -1.0], len(i))
    return sp.csr_matrix((data, indices, np.arange(0, 2 * len(i) + 1, 2)), shape=(len(i), n))


class NearSolver(Solver):
    """``P^-1 f`` by truncated CG (module docstring), ``P = P_springs + R``:
    ``springs`` the springs model's solver (its ``solve`` and ``dot``),
    ``R = D^T blockdiag(blocks) D`` with ``incidence`` ``D`` (P, N) the
    pairs' (:func:`pair_incidence`) and ``blocks`` (P, dim, dim) their
    repulsion blocks (force per length), ``free`` (N, dim) the free mask,
    ``rigid`` the rigid motions (orthonormal columns on the free degrees of
    freedom), ``work`` where the products are counted."""

    def __init__(self, springs: Any, incidence: sp.csr_matrix, blocks: np.ndarray,
                 free: np.ndarray, rigid: np.ndarray, work: Work):
        self.springs, self.incidence, self.blocks = springs, incidence, blocks
        self.free, self.rigid, self.work = free, rigid, work
        self.dim = free.shape[1]

    def _r(self, v: np.ndarray) -> np.ndarray:
        """``R v`` (N, 3) on the free coordinates, one product counted."""
        self.work.near_products += 1
        stretch = self.incidence @ v[:, :self.dim]
        out = np.zeros_like(v)
        out[:, :self.dim] = self.incidence.T @ np.einsum('pab,pb->pa', self.blocks, stretch)
        return held_at_zero(out, self.free)

    def dot(self, v: np.ndarray) -> np.ndarray:
        """``P v`` (N, 3), force per length, zero on held coordinates (the
        springs' part by its own product: for a check, not the CG)."""
        v = held_at_zero(np.array(v, dtype=float).reshape(-1, 3), self.free)
        return self.springs.dot(v) + self._r(v)

    def solve(self, forces: np.ndarray) -> np.ndarray:
        residual = held_at_zero(np.array(forces, dtype=float).reshape(-1, 3), self.free)
        move = self._cg(residual)
        flat = move[:, :self.dim][self.free]
        move[:, :self.dim][self.free] = flat - self.rigid @ (self.rigid.T @ flat)
        return move

    def _cg(self, residual: np.ndarray) -> np.ndarray:
        """CG on ``P d = residual`` preconditioned by ``P_springs``, to the
        relative residual :data:`NEAR_RTOL`; on negative curvature the
        iterate so far (the springs model's move at the first). ``P z = r +
        R z`` for ``z = P_springs^-1 r``; ``P d`` follows ``d``'s recursion."""
        move = np.zeros_like(residual)
        z = self.springs.solve(residual)
        direction, rz = z, np.vdot(residual, z)
        product = residual + self._r(z)
        goal = NEAR_RTOL * np.linalg.norm(residual)
        for k in range(NEAR_MAXITER):
            curvature = np.vdot(direction, product)
            if not curvature > 0:
                return move if k else z
            alpha = rz / curvature
            move += alpha * direction
            residual = residual - alpha * product
            if np.linalg.norm(residual) <= goal or k == NEAR_MAXITER - 1:
                break
            z = self.springs.solve(residual)
            rz, last = np.vdot(residual, z), rz
            direction = z + (rz / last) * direction
            product = residual + self._r(z) + (rz / last) * product
        return move
