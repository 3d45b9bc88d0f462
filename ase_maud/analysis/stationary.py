"""Classify a configuration of the Maud potential by its Hessian d2E/dr dr.

:func:`classify` returns a :class:`StationaryPoint`: the eigenvalues of ``H``
(units of ``Q``) on the degrees of freedom that are free to move, with the
rigid-body modes removed, the count of negative, zero and positive ones, and a
verdict. Three paths give the same counts:

- ``dense``: every eigenvalue, from :meth:`MaudCalculator.get_hessian` and
  ``numpy.linalg.eigh``; for up to :data:`DENSE_MAX_DOFS` free degrees of
  freedom.
- ``lowest``: the lowest ``k`` eigenvalues of the same dense Hessian (LAPACK's
  ``syevr`` asked for those only), on request.
- ``iterative``: the lowest ``k`` eigenvalues by LOBPCG on Hessian-vector
  products (:meth:`ase_maud.calculator.potential.MaudPotential.hvp`), O(N) memory,
  O(N**2) time per product, a block of vectors per pass over the pairs,
  above :data:`DENSE_MAX_DOFS`; to the digits the signs need
  (:func:`_lowest_spectrum`). The
  preconditioner is :func:`near_field_stiffness`, a sparse positive model of
  ``H`` (springs and close pairs), factorised once: the near field carries
  the conditioning, so the number of products hardly grows with N (``eigsh``
  with a shift-invert needs a factorisation of ``H``, which is dense).

Removed modes. Fixed degrees of freedom (:class:`~ase.constraints.FixAtoms`,
:class:`~ase.constraints.FixCartesian`) are projected out by keeping only the
rows and columns of the free ones. The rigid-body modes (translations and
rotations, 3 + 3 in 3D, 2 + 1 in 2D) that move no fixed degree of freedom are
projected out too: all of them for a free scene, fewer for a collinear one
(a rotation about the line moves nothing), none once three non-collinear
points are fixed.

Tolerance. An eigenvalue counts as zero when ``|lambda| <= rtol * max|lambda|``
(default ``rtol`` = :data:`RTOL` = 1e-8). Rounding in building ``H`` and in the
eigensolver leaves errors near ``1e-16 * max|lambda| * sqrt(dim N)``, about
1e-14 of the largest here; a configuration relaxed to a small ``fmax`` has
eigenvalues of order ``fmax / L`` wrong. 1e-8 sits well above the first and
still resolves modes a hundred million times softer than the stiffest. Maxima
do not occur unless FixCartesian holds only some coordinates of a point: every
nodal block has trace ``3 Q deg(m) >= 0`` in 3D (``1/L`` is harmonic) and more
in 2D, and a maximum needs a negative trace.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian
from scipy.sparse.linalg import LinearOperator, eigsh, lobpcg, splu
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist

from ase_maud.counting import Work
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import free_dofs, project_off, rigid_body_modes
from ase_maud.physics.topology import mean_spring_length

#: Eigenvalues with ``|lambda| <= RTOL * max|lambda|`` count as zero.
RTOL = 1e-8
#: ``method='auto'`` takes every eigenvalue up to this many free degrees of
#: freedom (a dense Hessian of 8 MB), the lowest by LOBPCG above: no array
#: of N x N there (docs/analysis.md compares the two above it).
DENSE_MAX_DOFS = 1000
#: Default force tolerance for "stationary", in units of ``Q a``.
FTOL = 1e-6


@dataclass(frozen=True)
class StationaryPoint:
    """What the Hessian says about a configuration (built by :func:`classify`).

    ``eigenvalues`` and ``modes`` cover every mode (``method='dense'``) or the
    lowest ``k`` (``'lowest'``, ``'iterative'``); the counts always cover all
    ``n_modes`` free, non-rigid modes. 'degenerate': some non-rigid eigenvalue
    within ``tolerance`` of zero. If ``stationary`` is False the verdict
    describes the curvature at a point that is not stationary.

    Parameters
    ----------
    verdict : {'minimum', 'saddle', 'maximum', 'degenerate'}
        What kind of point.
    index : int
        The number of negative curvatures (the saddle's order).
    eigenvalues : ndarray of shape (m,)
        Ascending curvatures in ``Q`` (energy per length squared).
    modes : ndarray of shape (m, N, 3)
        Unit vectors of the modes, zero on fixed coordinates.
    n_negative, n_zero, n_positive : int
        The counts over all free, non-rigid modes.
    n_rigid, n_fixed : int
        Rigid-body modes and fixed coordinates left out.
    tolerance : float
        The zero tolerance, ``rtol * max|lambda|`` (``Q``).
    fmax, ftol : float
        The largest force and the tolerance it was judged by (``Q a``).
    stationary : bool
        ``fmax <= ftol``.
    method : {'dense', 'lowest', 'iterative'}
        The path taken.
    """

    verdict: str
    index: int
    eigenvalues: np.ndarray
    modes: np.ndarray
    n_negative: int
    n_zero: int
    n_positive: int
    n_rigid: int
    n_fixed: int
    tolerance: float
    fmax: float
    ftol: float
    stationary: bool
    method: str

    @property
    def n_modes(self) -> int:
        """Free, non-rigid modes counted by the verdict."""
        return self.n_negative + self.n_zero + self.n_positive


def force_tolerance(potential, ftol: float | None = None,
                    positions: np.ndarray | None = None) -> float:
    """``ftol``, by default :data:`FTOL` ``* Q a`` of the
    :class:`~ase_maud.calculator.potential.MaudPotential` ``potential`` (force units):
    the largest ``|f|`` of a stationary point. At ``a = 0`` (no repulsion,
    no length of its own) ``a`` is replaced by the mean spring length at
    ``positions`` (N, 3), or 1 without them or without springs."""
    if ftol is not None:
        return ftol
    if potential.repulsive:
        return FTOL * potential.force_unit
    if positions is None or not len(potential.springs):
        return FTOL * potential.Q
    return FTOL * potential.Q * mean_spring_length(positions, potential.springs)


def free_mask(atoms: Atoms, dim: int) -> np.ndarray:
    """Boolean (N, dim) mask of the free degrees of freedom.

    Only :class:`FixAtoms` and :class:`FixCartesian` are understood; any other
    constraint is a ValueError (its projection would not be a coordinate one).
    """
    for constraint in atoms.constraints:
        if not isinstance(constraint, (FixAtoms, FixCartesian)):
            raise ValueError(f'cannot classify with the constraint '
                             f'{constraint!r}: only FixAtoms and FixCartesian')
    return free_dofs(atoms, dim)


def hessian_operator(atoms: Atoms, free: np.ndarray | None = None,
                     rigid: np.ndarray | None = None,
                     work: Work | None = None) -> LinearOperator:
    """``H`` on the free degrees of freedom as a LinearOperator, never dense.

    ``free`` (N, dim) and ``rigid`` (orthonormal columns) default to
    :func:`free_mask` and :func:`rigid_body_modes`; the operator is
    ``P H P`` with ``P`` the projector off the rigid modes, so they have
    eigenvalue 0. A block of vectors is multiplied in one pass over the pairs;
    each vector is counted in ``work`` (:attr:`Work.hvp_vectors`) if given.
    """
    calc = atoms.calc
    potential = calc.potential
    positions = calc.check_atoms(atoms)
    free = free_mask(atoms, potential.dim) if free is None else free
    if rigid is None:
        rigid = rigid_body_modes(positions, free, potential.dim)
    flat = free.ravel()

    def project(x):
        return x - rigid @ (rigid.T @ x)

    def matmat(x):
        if work is not None:
            work.hvp_vectors += x.shape[1]
        full = np.zeros((flat.size, x.shape[1]))
        full[flat] = project(x)
        hx = potential.hvp(positions, full.T.reshape(-1, *free.shape))
        return project(hx.reshape(x.shape[1], -1).T[flat])

    n = int(flat.sum())
    return LinearOperator((n, n), matvec=lambda v: matmat(v.reshape(-1, 1)),
                          matmat=matmat, dtype=float)


def classify(atoms: Atoms, method: str = 'auto', k: int = 6,
             rtol: float = RTOL, ftol: float | None = None,
             work: Work | None = None, guess: np.ndarray | None = None) -> StationaryPoint:
    """Classify ``atoms`` (with a MaudCalculator) by its Hessian.

    Parameters
    ----------
    atoms : Atoms
        The configuration, with a :class:`~ase_maud.MaudCalculator` and its
        constraints (fixed coordinates are left out).
    method : 'auto', 'dense', 'lowest' or 'iterative'
        ``auto`` is dense up to :data:`DENSE_MAX_DOFS` free degrees of freedom,
        iterative above; iterative is lowest below ``5 k`` modes (LOBPCG's need).
    k : int
        Eigenvalues the lowest and iterative paths compute (the lowest). If all are
        negative the index is not known and a ValueError asks for a larger k.
    rtol : float
        Zero tolerance relative to the largest ``|lambda|``.
    ftol : float
        Force (units of ``Q a``) above which the point is flagged and warned
        about as not stationary; default :data:`FTOL` ``* Q a``.
    work : Work
        If given, counts the dense Hessian or the Hessian-vector products.
    guess : ndarray of shape (m, N, 3), m <= k, or None
        Moves the iterative path starts from (modes a climb followed, say; the
        rest random): its cost depends on them, not its answer. Dense: unused.

    Returns
    -------
    StationaryPoint
        The verdict, the index (negative curvatures), the eigenvalues (``Q``,
        ascending) and modes on the free, non-rigid coordinates.

    Raises
    ------
    ValueError
        An unknown ``method``; the ``k`` lowest eigenvalues all negative
        or zero (the index is not known: ask for a larger ``k``); ``dense``
        on more atoms than ``MaudCalculator.max_hessian_atoms``; atoms the
        calculator refuses.

    Warns
    -----
    UserWarning
        ``not a stationary point: fmax = ... > ftol``: the verdict describes
        the curvature there only.
    """
    calc = atoms.calc
    potential = calc.potential
    dim = potential.dim
    positions = calc.check_atoms(atoms)
    free = free_mask(atoms, dim)
    rigid = rigid_body_modes(positions, free, dim)
    n_modes = int(free.sum()) - rigid.shape[1]
    if method == 'auto':
        method = 'dense' if free.sum() <= DENSE_MAX_DOFS else 'iterative'
    if method == 'iterative' and n_modes < 5 * k:   # too few coordinates for LOBPCG
        method = 'lowest'
    if method == 'dense':
        values, vectors = _dense_spectrum(atoms, free, rigid)
        scale = np.abs(values).max(initial=0.0)
    elif method == 'iterative':
        values, vectors, scale = _lowest_spectrum(atoms, free, rigid, k,
                                                  rtol, work, guess)
    elif method == 'lowest':
        values, vectors, scale = _lowest_of_dense(atoms, free, rigid, k)
    else:
        raise ValueError(f"method must be 'auto', 'dense', 'lowest' or 'iterative', "
                         f'got {method!r}')
    if work is not None and method != 'iterative':
        work.hessians += 1
    tolerance = rtol * scale
    n_negative = int(np.sum(values < -tolerance))
    n_zero = int(np.sum(np.abs(values) <= tolerance))
    if len(values) < n_modes and values[-1] <= tolerance:
        raise ValueError(f'the lowest {len(values)} eigenvalues are all <= '
                         f'{tolerance:.3g}: the index is at least '
                         f'{n_negative}; ask for a larger k')
    n_positive = n_modes - n_negative - n_zero
    if n_zero:
        verdict = 'degenerate'
    elif n_negative == 0:
        verdict = 'minimum'
    elif n_positive == 0:
        verdict = 'maximum'
    else:
        verdict = 'saddle'
    modes = np.zeros((len(values), len(atoms), 3))
    modes[:, :, :dim][:, free] = vectors.T
    fmax = float(np.linalg.norm(atoms.get_forces(), axis=1).max(initial=0.0))
    ftol = force_tolerance(potential, ftol, atoms.positions)
    if fmax > ftol:
        warnings.warn(f'not a stationary point: fmax = {fmax:.3g} > '
                      f'{ftol:.3g}; the verdict {verdict!r} describes the '
                      'curvature there only', stacklevel=2)
    return StationaryPoint(
        verdict=verdict, index=n_negative, eigenvalues=values, modes=modes,
        n_negative=n_negative, n_zero=n_zero, n_positive=n_positive,
        n_rigid=rigid.shape[1], n_fixed=int((~free).sum()),
        tolerance=tolerance, fmax=fmax, ftol=ftol, stationary=fmax <= ftol,
        method=method)


def _free_hessian(atoms, free):
    """The dense Hessian on the free dofs (``free``: mask (N, dim)): the
    calculator's whole Hessian there, or its block
    (:meth:`.MaudCalculator.hessian_rows`)."""
    rows = atoms.calc.hessian_rows(atoms, free)
    if rows is None:
        flat = free.ravel()
        return atoms.calc.get_hessian(atoms)[np.ix_(flat, flat)]
    kept = np.flatnonzero(free[rows].ravel())
    return atoms.calc.get_hessian_block(atoms, rows)[np.ix_(kept, kept)]


def _dense_spectrum(atoms, free, rigid):
    """All eigenpairs of ``H`` on the free dofs orthogonal to ``rigid``."""
    hessian = _free_hessian(atoms, free)
    basis = scipy.linalg.null_space(rigid.T) if rigid.size else np.eye(len(hessian))
    values, vectors = np.linalg.eigh(basis.T @ hessian @ basis)
    return values, basis @ vectors


def _lowest_of_dense(atoms, free, rigid, k):
    """The lowest ``k`` eigenpairs of ``H`` on the free dofs orthogonal to
    ``rigid``, and max|lambda| (to 1 %, Lanczos on the dense Hessian): ``P H
    P`` (``P`` the projector off the rigid modes) with the rigid modes lifted
    above every eigenvalue."""
    hessian = _free_hessian(atoms, free)
    project_off(hessian, rigid)
    v0 = np.random.default_rng(0).standard_normal(len(hessian))
    scale = abs(eigsh(hessian, 1, which='LM', tol=0.01, v0=v0,
                      return_eigenvectors=False)[0])
    hessian += 2 * scale * rigid @ rigid.T
    k = min(k, len(hessian) - rigid.shape[1])
    values, vectors = scipy.linalg.eigh(hessian, subset_by_index=[0, k - 1],
                                        overwrite_a=True, check_finite=False)
    return values, vectors, scale


def _lowest_spectrum(atoms, free, rigid, k, rtol, work=None, guess=None):
    """Lowest ``k`` eigenpairs by preconditioned LOBPCG (its first vectors
    ``guess`` if given, see :func:`classify`), and max|lambda|.

    Iterates stay orthogonal to the rigid modes (LOBPCG's ``Y``). A first run
    stops at residuals ``r = |H x - lambda x|`` below :data:`LOBPCG_FIRST_RTOL`
    of the largest eigenvalue; it is the answer if every ``r`` settles a sign
    (below :data:`SIGN_MARGIN` times ``|lambda|`` less the zero tolerance
    ``rtol max|lambda|``: an eigenvalue lies within ``r`` of ``lambda``) or a
    zero (below a tenth of that tolerance), else a second run goes on to a
    tenth of the zero tolerance (a warning if a sign is still open).
    """
    op = hessian_operator(atoms, free, rigid, work)
    flat = free.ravel()
    near = near_field_stiffness(atoms)[np.ix_(flat, flat)]
    # definite (the translations are its null space), yet no blur of modes
    # down to 1e-4 of the stiffest
    shift = 1e-4 * abs(near).sum(axis=1).max()
    lu = splu(sp.csc_matrix(near + shift * sp.identity(near.shape[0])))
    precond = LinearOperator(near.shape, matvec=lu.solve, matmat=lu.solve, dtype=float)
    vectors = np.random.default_rng(0).standard_normal((op.shape[0], k))
    top = eigsh(op, 1, which='LA', tol=0.1, ncv=min(10, op.shape[0]),
                v0=vectors[:, 0], return_eigenvectors=False)[0]  # a 1% scale
    if guess is not None:
        start = np.asarray(guess, dtype=float)[:k, :, :free.shape[1]][:, free].T
        vectors[:, :start.shape[1]] = start
    zero = rtol * abs(top)
    for tol in (LOBPCG_FIRST_RTOL * abs(top), 0.1 * zero):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', UserWarning)   # "not reaching the tol"
            values, vectors = lobpcg(op, vectors, M=precond,
                                     Y=rigid if rigid.size else None,
                                     tol=tol, maxiter=LOBPCG_MAXITER, largest=False)
        residuals = np.linalg.norm(op @ vectors - vectors * values, axis=0)
        settled = ((residuals < 0.1 * zero)
                   | (residuals < SIGN_MARGIN * (np.abs(values) - zero)))
        if settled.all():
            break
    else:
        warnings.warn(f'LOBPCG: residuals {np.array2string(residuals[~settled], precision=3)}'
                      f' leave the signs of {np.array2string(values[~settled], precision=3)}'
                      f' open after {LOBPCG_MAXITER} iterations', stacklevel=3)
    order = np.argsort(values)
    values, vectors = values[order], vectors[:, order]
    return values, vectors, max(abs(values[0]), abs(top))


#: :func:`_lowest_spectrum`: the first run's residuals relative to the largest
#: eigenvalue, each run's iterations, and the share of a Ritz value's distance
#: from the zero band its residual must be below to settle its sign.
LOBPCG_FIRST_RTOL, LOBPCG_MAXITER, SIGN_MARGIN = 1e-6, 500, 0.5


def near_field_stiffness(atoms: Atoms, cutoff: float = 1.5) -> sp.csr_matrix:
    """Positive semi-definite sparse model of ``H``, shape (dim N, dim N).

    The Hessian of the near field (every sprung pair and every pair closer
    than ``cutoff`` times the median nearest-neighbour distance), with each
    pair block ``B_ij`` replaced by its absolute value ``|B_ij|`` (same
    eigenvectors, eigenvalues made positive): the repulsion's
    ``-c / L**3`` across a pair flips sign, so the sum of pair terms
    ``(e_i - e_j)(e_i - e_j)^T (x) |B_ij|`` is positive semi-definite by
    construction, with the translations as its null space. It equals the near
    field's Hessian wherever every pair block is already positive.
    """
    potential = atoms.calc.potential
    dim = potential.dim
    x = potential.reduced(atoms.positions)[:, :dim]   # units of a: Q times unit blocks
    n = len(x)
    tree = cKDTree(x)
    spacing = np.median(tree.query(x, k=2)[0][:, 1])
    close = tree.query_pairs(cutoff * spacing, output_type='ndarray')
    springs = np.sort(potential.springs, axis=1)
    pairs, where = np.unique(np.vstack([springs, np.sort(close, axis=1)]),
                             axis=0, return_inverse=True)
    i, j = pairs.T
    d = x[i] - x[j]
    blocks = physics.repulsion_block(d)
    sprung = where[:len(springs)]
    blocks[sprung] += physics.spring_block(d[sprung], potential.stiffnesses)
    blocks *= potential.Q
    values, vectors = np.linalg.eigh(blocks)
    blocks = np.einsum('pak,pk,pbk->pab', vectors, np.abs(values), vectors)
    return physics.pair_block_laplacian(i, j, blocks, n)


def displace_along_mode(atoms: Atoms, point: StationaryPoint, mode: int = 0,
                        step: float | None = None) -> tuple[Atoms, Atoms]:
    """Two copies of ``atoms`` pushed both ways along an unstable mode.

    ``mode`` counts the negative eigenvalues of ``point`` (a
    :class:`StationaryPoint` of ``atoms``) from the most negative; ``step`` is
    the largest displacement of any point (default ``0.1 a``). Each copy gets
    a fresh calculator with the same parameters, ready to be relaxed into the
    minimum on its side of the saddle.

    Parameters
    ----------
    atoms : Atoms
        The saddle, with a :class:`~ase_maud.MaudCalculator`.
    point : StationaryPoint
        :func:`classify` of ``atoms``.
    mode : int, default 0
        Which unstable mode (0 the most negative).
    step : float or None, default None
        The largest displacement of a point, in the unit of ``a`` (None:
        ``0.1 a``).

    Returns
    -------
    tuple of two Atoms
        The copies moved ``+step`` and ``-step`` along the mode.

    Raises
    ------
    ValueError
        ``mode`` is not one of the point's negative curvatures.
    """
    if not 0 <= mode < point.n_negative:
        raise ValueError(f'mode {mode} is not unstable: the point has '
                         f'{point.n_negative} negative eigenvalues')
    calc = atoms.calc
    step = 0.1 * calc.potential.a if step is None else step
    vector = point.modes[mode]
    vector = step * vector / np.linalg.norm(vector, axis=1).max()
    copies = []
    for sign in (1, -1):
        copy = atoms.copy()
        copy.positions += sign * vector
        copy.calc = type(calc)(**calc.parameters)
        copies.append(copy)
    return tuple(copies)


#: Default tolerances of :func:`same_point`: energies relative, pair
#: distances in length units (for scenes relaxed to fmax 1e-6 ``Q a``, whose
#: energies agree to ~1e-12 and distances to ~1e-7 a).
ENERGY_RTOL, DISTANCE_ATOL = 1e-8, 1e-4

def same_point(a: Atoms, b: Atoms, energy_rtol: float = ENERGY_RTOL,
               distance_atol: float = DISTANCE_ATOL) -> bool:
    """Whether ``a`` and ``b`` are the same configuration up to rigid motion and
    relabelling: energies within ``energy_rtol`` (relative) and sorted pair
    distances within ``distance_atol`` (length units).

    Parameters
    ----------
    a, b : Atoms
        The two configurations, each with a calculator, as many points.
    energy_rtol : float, default 1e-8
        The energies' relative tolerance.
    distance_atol : float, default 1e-4
        The sorted pair distances' tolerance, in the unit of ``a``.

    Returns
    -------
    bool
        True if the same point up to rigid motion and relabelling.

    Raises
    ------
    ValueError
        The two have different numbers of points, or a calculator refuses
        its atoms.
    """
    ea, eb = a.get_potential_energy(), b.get_potential_energy()
    if abs(ea - eb) > energy_rtol * max(abs(ea), abs(eb)):
        return False
    return bool(np.abs(np.sort(pdist(a.positions)) - np.sort(pdist(b.positions))).max()
                <= distance_atol)
