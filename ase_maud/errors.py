"""Every error class of ase_maud, in one place: what a run, a file or an
argument can go wrong with. All derive from :class:`MaudError` (a
``RuntimeError``), but for the restart file's, which is also a ``ValueError``.
"""

from __future__ import annotations

from ase.optimize import RestartError


class MaudError(RuntimeError):
    """A run that cannot go on; the message (also in the log) says why.

    Attributes
    ----------
    args : tuple of str
        ``(message,)``: what went wrong and what to do, as the run's log
        has it too (every subclass alike).

    Notes
    -----
    The base of every error of ase_maud but :class:`RestartFileError`; a
    ``RuntimeError``. Raised itself by :meth:`ase_maud.Maud.run` when the
    calculator returns a non-finite energy, force or Hessian (the positions
    are put back to the last finite step), and by the command line's runs.
    Catch it to catch them all (``except MaudError``).
    """


class DivergenceError(MaudError):
    """The points flew apart: the scene has no finite stationary point.

    Notes
    -----
    Raised by :meth:`ase_maud.Maud.run` on a :class:`~ase_maud.MaudCalculator`'s
    scene where no finite minimum is proved, when at two successive growths
    of the scene (by ``divergence_factor``) its forces came no nearer a
    balance. ``divergence_factor=inf`` switches the test off.
    """


class StagnationError(MaudError):
    """No progress: gamma underflowed or fmax stopped improving.

    Notes
    -----
    Raised by :meth:`ase_maud.Maud.run` after ``patience`` steps without a new
    best fmax or a real fall of the energy (a creep of less than ``1e-3 fmax``
    times the scene's size), or when every step raised the energy until the
    step factor underflowed: an ``fmax`` below the forces' rounding noise,
    an oscillation, or a noisy calculator.
    """


class WrongIndexError(MaudError):
    """A saddle search (``target='saddle'``) converged on a stationary point
    whose index (negative curvatures of the analytic Hessian) is not the
    ``order`` it sought.

    Notes
    -----
    Raised by :meth:`ase_maud.Maud.run` with ``target='saddle'``; the message
    gives the index found and the lowest curvatures (``Q``). Try another
    ``mode=`` or start, or :func:`ase_maud.search_saddles`.
    """


class NoEquilibriumError(MaudError):
    """The scene can have no finite equilibrium (a net load that nothing
    holds, spring components that fly away); raised before the first step,
    the message says what to fix.

    Notes
    -----
    Raised by :meth:`ase_maud.Maud.run` before the first step (the atoms are
    not moved): a net load along a direction nothing holds (any target), or
    spring components with no fixed atom in 3D (``target='minimum'``).
    """


class FileInUseError(MaudError):
    """Another run holds the lock of a file this run would write.

    Notes
    -----
    Raised when :class:`ase_maud.Maud` is created (its trajectory or restart
    arrays file locked by a run in this or another process), or at the first
    frame of ``ase-maud relax`` when another program wrote its trajectory in
    the meantime. A killed run leaves no lock.
    """



class RestartFileError(RestartError, ValueError):
    """A restart file that cannot be read, is damaged, or is of another
    layout or run: ASE's :class:`~ase.optimize.RestartError` (what ASE's
    optimizers raise for an unreadable restart file), and a ValueError (a
    bad argument: the file given). The message names the file and the
    field.

    Notes
    -----
    Raised by :meth:`ase_maud.Maud.run` (and :meth:`ase_maud.Maud.resume`)
    when they read the restart file.
    """
