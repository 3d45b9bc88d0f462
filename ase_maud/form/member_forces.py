"""What a form finder designs with: member forces, support reactions and the
out-of-balance of a net, in force units.

:func:`form_result` reads them off a net (an :class:`ase.Atoms` with a
:class:`~ase_maud.MaudCalculator`), relaxed or not, as a :class:`FormResult`
(in the manner of compas_fd's ``Result``); :func:`write_forces_csv` writes
them as one table.

Conventions (ASE's sign, ``f = -dE/dr``):

- A member is a spring ``s = (i, j)``. Its force density is ``Q q_s``
  (force per length, compas_fd's ``q``), its length ``L_s = |r_i - r_j|``,
  its force ``Q q_s L_s`` (a zero-length spring is always in tension:
  positive is tension).
- A support is a point that a constraint holds in all three directions
  (:func:`~ase_maud.physics.topology.fixed_atoms`: FixAtoms, or FixCartesian of every
  direction). Its reaction is the force the support exerts on the point:
  minus the sum of every force on it, springs, repulsion and loads (minus
  the calculator's force there, before constraints). The reactions of a net
  in equilibrium balance its loads: ``sum R + sum F = `` the sum of the
  residuals at the free points.
- At a free point, the out-of-balance of the structure is the sum of its
  members' pulls and its load; the repulsion ``a**3 Q / L`` is no member, so
  at Maud's equilibrium it carries that out-of-balance. ``a -> 0`` leaves the
  force-density method (docs/theory.md), where it is zero.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from ase import Atoms

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.files.atomic_replace import replace_text
from ase_maud.form.force_density import force_density_positions
from ase_maud.physics import pair_law as physics
from ase_maud.physics.topology import fixed_atoms, support_excursion, unsupported

__all__ = ['REPULSION_SHARE', 'FormResult', 'describe_result', 'form_result',
           'form_warnings', 'write_forces_csv']

#: The out-of-balance of the members and loads, over the mean member force,
#: above which the repulsion shapes the form (:func:`form_warnings`):
#: below it the form is the force-density equilibrium for a designer.
REPULSION_SHARE = 1e-3

#: The move as a whole, or the shrinking, of a net without supports, over
#: its diagonal, above which :func:`form_warnings` says so.
FREE_MOTION = 1e-3


@dataclass(frozen=True)
class FormResult:
    """Forces of a net (see the module docstring for the signs).

    Built by :func:`form_result`; a frozen record. Units: lengths in the
    positions' unit (that of ``a``), forces in ``Q a`` (force units),
    force densities in ``Q`` (force per length).

    Parameters
    ----------
    vertices : ndarray of shape (N, 3)
        The positions.
    edges : ndarray of shape (K, 2)
        The point indices of each member (spring).
    force_densities : ndarray of shape (K,)
        ``Q q_s`` of each member (force per length).
    lengths : ndarray of shape (K,)
        Each member's length.
    forces : ndarray of shape (K,)
        Each member's force ``Q q_s L_s`` (tension positive; a zero-length
        spring is never in compression).
    supports : ndarray of shape (M,)
        The indices of the points held in every direction.
    reactions : ndarray of shape (M, 3)
        The force each support exerts on its point.
    loads : ndarray of shape (N, 3)
        The loads (zero where there are none).
    residuals : ndarray of shape (N, 3)
        The total force (members, repulsion, loads) at each free point, ASE's
        sign; zero at the supports.
    out_of_balance : ndarray of shape (N, 3)
        The members' pulls plus the load at each free point (zero at the
        supports): what the repulsion carries at an equilibrium of Maud, and
        the force-density method's residual.
    """

    vertices: np.ndarray
    edges: np.ndarray
    force_densities: np.ndarray
    lengths: np.ndarray
    forces: np.ndarray
    supports: np.ndarray
    reactions: np.ndarray
    loads: np.ndarray
    residuals: np.ndarray
    out_of_balance: np.ndarray

    @property
    def max_force(self) -> float:
        """The member force of the largest size, with its sign (tension
        positive, compression negative; 0 without members)."""
        if not len(self.forces):
            return 0.0
        return float(self.forces[np.argmax(np.abs(self.forces))])

    @property
    def max_tension(self) -> float:
        """The largest tension (0 without members in tension)."""
        return float(self.forces.max(initial=0.0))

    @property
    def max_compression(self) -> float:
        """The largest compression, as a negative force (0 without members
        in compression, ``q < 0``)."""
        return float(self.forces.min(initial=0.0))

    @property
    def mean_force(self) -> float:
        """The mean size of the member forces (0 without members)."""
        return float(np.abs(self.forces).mean()) if len(self.forces) else 0.0

    @property
    def max_residual(self) -> float:
        """The largest ``|residual|`` at a free point: how far from any
        equilibrium the net is."""
        return _largest(self.residuals)

    @property
    def max_out_of_balance(self) -> float:
        """The largest ``|members' pulls + load|`` at a free point."""
        return _largest(self.out_of_balance)

    @property
    def repulsion_share(self) -> float:
        """:attr:`max_out_of_balance` over :attr:`mean_force`: how far the
        form is from the force-density (structural) equilibrium of its
        members and loads, the part the repulsion carries. 0 without members."""
        mean = self.mean_force
        return self.max_out_of_balance / mean if mean > 0 else 0.0

    @property
    def reaction_sum(self) -> np.ndarray:
        """The sum of the reactions, (3,): minus the sum of the loads for a
        net in equilibrium."""
        return self.reactions.sum(axis=0)


def _largest(rows: np.ndarray) -> float:
    return float(np.sqrt(np.einsum('ij,ij->i', rows, rows).max(initial=0.0)))


def form_result(atoms: Atoms) -> FormResult:
    """The member forces, reactions and out-of-balance of the net ``atoms``
    at its present positions (a :class:`FormResult`).

    ``atoms.calc`` must be a :class:`~ase_maud.MaudCalculator`; one force
    call (none if its forces are held). Supports are the points a constraint
    holds in all three directions; a point held in some directions only is
    treated as free (its residual then includes what the constraint takes).

    Parameters
    ----------
    atoms : Atoms
        The net, with a :class:`~ase_maud.MaudCalculator` and its supports as
        constraints.

    Returns
    -------
    FormResult
        Member forces (tension positive, ``Q a``), reactions (the force each
        support exerts on its point), residuals and out-of-balance (ASE's
        sign).

    Raises
    ------
    ValueError
        ``atoms.calc`` is not a MaudCalculator, or atoms it refuses.
    """
    calc = atoms.calc
    if not isinstance(calc, MaudCalculator):
        raise ValueError('form_result needs a net with a MaudCalculator attached, got '
                         f'{type(calc).__name__}')
    potential = calc.potential
    positions = atoms.get_positions()
    total = atoms.get_forces(apply_constraint=False)
    springs = potential.springs
    density = potential.Q * np.broadcast_to(potential.stiffnesses, len(springs))
    d = positions[springs[:, 0]] - positions[springs[:, 1]]
    lengths = np.linalg.norm(d, axis=1)
    _, pulls = physics.spring_terms(positions, springs, density)
    loads = np.zeros((len(atoms), 3)) if potential.loads is None else potential.loads
    if potential.dim == 2:
        pulls[:, 2] = 0.0
    held = fixed_atoms(atoms)
    free = ~held[:, None]
    return FormResult(
        vertices=positions, edges=springs.copy(), force_densities=np.array(density),
        lengths=lengths, forces=density * lengths,
        supports=np.flatnonzero(held), reactions=-total[held],
        loads=np.array(loads), residuals=np.where(free, total, 0.0),
        out_of_balance=np.where(free, pulls + loads, 0.0))


def write_forces_csv(path: str | Path, result: FormResult) -> Path:
    """Write ``result`` as one CSV table to ``path``; return it.

    Columns ``kind, i, j, force, length, force_density, rx, ry, rz``: a row
    ``member`` per member (points ``i``, ``j``; ``force`` in force units,
    tension positive; ``length``; ``force_density`` ``Q q`` in force per
    length), then a row ``reaction`` per support (point ``i``; ``force`` the
    reaction's size and ``rx, ry, rz`` its components: the force the support
    exerts on the point). Numbers in full precision (``repr``); the file is
    replaced whole (:mod:`ase_maud.files.atomic_replace`).

    Parameters
    ----------
    path : str or Path
        The CSV file to write.
    result : FormResult
        What :func:`form_result` gave.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    ValueError
        A path that cannot be written (a missing or read-only directory, a
        directory).
    OSError
        The disk refused the write (the old file is left whole).
    """
    path = Path(path)
    text = io.StringIO()
    table = csv.writer(text)
    table.writerow(['kind', 'i', 'j', 'force', 'length', 'force_density',
                    'rx', 'ry', 'rz'])
    for (i, j), force, length, density in zip(
            result.edges.tolist(), result.forces.tolist(), result.lengths.tolist(),
            result.force_densities.tolist(), strict=True):
        table.writerow(['member', i, j, repr(force), repr(length), repr(density),
                        '', '', ''])
    for n, reaction in zip(result.supports.tolist(), result.reactions, strict=True):
        table.writerow(['reaction', n, '', repr(float(np.linalg.norm(reaction))), '', '',
                        *map(repr, reaction.tolist())])
    replace_text(path, text.getvalue(), newline='')
    return path


def describe_result(result: FormResult, repulsion: bool = True) -> str:
    """The numbers of ``result`` a structural engineer reads first, in one
    phrase.

    Parameters
    ----------
    result : FormResult
        What :func:`form_result` gave.
    repulsion : bool, default True
        Whether the net was relaxed with the repulsion (``a > 0``): then,
        where it matters, the phrase ends with the force the repulsion holds
        that no member or load does.

    Returns
    -------
    str
        The largest member force (the largest tension and compression where
        there are both), the sum of the support reactions against the sum of
        the loads and the largest unbalanced force left at a free point;
        forces in ``Q a``.

    Raises
    ------
    None
        It reads the record only.
    """
    def vector(values):
        return '(' + ', '.join(f'{v:.4g}' for v in np.asarray(values).tolist()) + ')'

    tension, compression = result.max_tension, result.max_compression
    members = (f'largest member force {result.max_force:.4g}'
               + (f' (tension up to {tension:.4g}, compression down to {compression:.4g})'
                  if tension > 0 and compression < 0 else
                  ' (compression)' if compression < 0 else ''))
    words = (f'{members}, support reactions sum to {vector(result.reaction_sum)} '
             f'against loads of {vector(result.loads.sum(axis=0))}, largest unbalanced '
             f'force at a free point {result.max_residual:.3g}')
    held = result.max_out_of_balance
    if repulsion and held > max(10 * result.max_residual, 1e-9 * result.mean_force):
        words += (f'; the repulsion holds up to {held:.3g} at a free point '
                  f'({result.repulsion_share:.2g} x the mean member force)')
    return words


def _moved_by_repulsion(atoms: Atoms) -> tuple[float, float, str] | None:
    """How far the repulsion has moved the net ``atoms`` from the form of
    its members and loads alone, the diagonal of the net's bounding box and
    what was measured: the largest distance of a point from the
    force-density equilibrium where the supports make that unique, else how
    far the free points reach beyond the supports' bounding box (and that
    box's diagonal); None if neither can be said (nothing fixed)."""
    if unsupported(atoms, atoms.calc.springs, atoms.calc.dim) is None:
        reference = force_density_positions(atoms)
        gap = float(np.linalg.norm(atoms.positions - reference, axis=1).max())
        diagonal = float(np.linalg.norm(np.ptp(reference, axis=0)))
        return gap, diagonal, 'moves the form from that equilibrium by up to'
    beyond, diagonal = support_excursion(atoms)
    if diagonal == 0:
        return None
    return beyond, diagonal, "inflates it: the free points reach beyond the supports' box by"


def form_warnings(atoms: Atoms, start: np.ndarray, result: FormResult) -> list[str]:
    """What a designer should be told of the relaxed net ``atoms`` (moved
    from ``start``, (N, 3)), each in one sentence: a repulsion that carries
    more than :data:`REPULSION_SHARE` of the mean member force and has moved
    the form by more than a tenth of its diagonal from the force-density
    equilibrium of its members and loads (where the supports make that
    unique; else free points beyond the supports' bounding box by that
    much: loads that hang a net below its supports are no reason); a net
    without supports that moved as a whole or shrank by more than
    :data:`FREE_MOTION` of its diagonal."""
    warnings = []
    a = atoms.calc.potential.a
    if a > 0 and result.repulsion_share > REPULSION_SHARE:
        moved = _moved_by_repulsion(atoms)
        if moved is not None:
            gap, diagonal, what = moved
            if gap > diagonal / 10:
                warnings.append(
                    f'the repulsion of a = {a:.4g} carries {result.repulsion_share:.2g} of '
                    f'the mean member force and {what} {gap:.3g} (diagonal {diagonal:.3g}): '
                    "a smaller --a gives a form closer to the members' own (--a 0: the "
                    'force-density equilibrium)')
    if not len(result.supports) and len(atoms) > 1:
        size = float(np.linalg.norm(np.ptp(start, axis=0)))
        moved = float(np.linalg.norm(atoms.positions.mean(axis=0) - start.mean(axis=0)))
        spread = [float(np.sqrt(((x - x.mean(axis=0))**2).sum(axis=1).mean()))
                  for x in (start, atoms.positions)]
        shrank = spread[0] - spread[1]
        if size > 0 and max(moved, shrank) > FREE_MOTION * size:
            warnings.append(
                f'the net has no supports: it moved as a whole by {moved:.3g} and its '
                f'spread about its centre shrank by {shrank:.3g} (diagonal {size:.3g}); '
                'fix points (--fix) to hold it where it is')
    return warnings
