"""Every error class of ase_maud, in one place: what a run, a file or an
argument can go wrong with. All derive from :class:`MaudError` (a
``RuntimeError``), but for the restart file's, which is also a ``ValueError``.
"""

from __future__ import annotations

from ase.optimize import RestartError


class MaudError(RuntimeError):
    """A run that cannot go on; the message (also in the log) says why."""


class DivergenceError(MaudError):
    """The points flew apart: the scene has no finite stationary point."""


class StagnationError(MaudError):
    """No progress: gamma underflowed or fmax stopped improving."""


class WrongIndexError(MaudError):
    """A saddle search (``target='saddle'``) converged on a stationary point
    whose index (negative curvatures of the analytic Hessian) is not the
    ``order`` it sought."""


class NoEquilibriumError(MaudError):
    """The scene can have no finite equilibrium (a net load that nothing
    holds, spring components that fly away); raised before the first step,
    the message says what to fix."""


class FileInUseError(MaudError):
    """Another run holds the lock of a file this run would write."""



class RestartFileError(RestartError, ValueError):
    """A restart file that cannot be read, is damaged, or is of another
    layout or run: ASE's :class:`~ase.optimize.RestartError` (what ASE's
    optimizers raise for an unreadable restart file), and a ValueError (a
    bad argument: the file given). The message names the file and the
    field."""
