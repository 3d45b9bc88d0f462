"""The ``fmm`` backend: the unit repulsion ``sum_{i<j} 1/L_ij`` in O(N).

The repulsion is the 3D Laplace kernel, so FMM3D's ``lfmm3d`` (package
``fmm3dpy``, the optional extra ``pip install ase-maud[fmm]``) gives at every
point the potential of all the others, its gradient and its Hessian. FMM3D's
kernel is ``1/(4 pi r)`` and it drops each point's own term; with unit charges

- ``energy = 2 pi * sum_i pot_i`` (each pair once);
- ``forces = -4 pi * grad``: minus the gradient of the potential felt at
  ``x_i``, which is ``f_i = sum_j d_ij / L_ij**3`` (:mod:`ase_maud.physics`);
- ``blocks = 4 pi * hess``: the Hessian of that potential with respect to
  ``x_i``, ``sum_j (3 d d^T / L**5 - I / L**3)``, in the same xx, yy, zz, xy,
  xz, yz order as :mod:`.base`.

The sums are approximate: ``fmm_eps`` is FMM3D's requested relative
precision, and the measured error of the energy, of the largest force and of
the blocks, relative to their largest entry, stays below ``fmm_eps``. Points
on a plane (2D scenes) work as they are. The result is not a smooth function of the
positions at the ``fmm_eps`` level (the octree changes as points move), so a
relaxation can only resolve forces down to about ``fmm_eps`` times the
typical repulsive force: ask for a small ``fmm_eps`` to relax tightly.

Cost is O(N), parallel over ``OMP_NUM_THREADS``, with about 10 ms of fixed
cost per call. Against the numba direct sum on one thread (random points in
3D) it breaks even near N = 4000 at ``fmm_eps = 1e-3`` and beyond N = 16000 at
``1e-6`` (near 12000 with the blocks); below a few hundred points FMM3D sums
directly and the result is exact to rounding.
"""

from __future__ import annotations

from numbers import Real

import numpy as np

from .base import Backend, Result

#: FMM3D's Laplace kernel is ``1 / (4 pi r)``; the repulsion's is ``1 / r``.
FMM3D_SCALE = 4.0 * np.pi


def check_eps(eps: object) -> None:
    """Raise ValueError unless ``eps`` is a real number in (0, 1)."""
    if not (isinstance(eps, Real) and 0.0 < eps < 1.0):
        raise ValueError(f'fmm_eps must be a number in (0, 1), the requested '
                         f'relative precision, got {eps!r}')


def _lfmm3d():
    """FMM3D's Laplace FMM, or ImportError saying how to install it."""
    try:
        from fmm3dpy import lfmm3d
    except ImportError as err:
        raise ImportError("backend='fmm' needs fmm3dpy: "
                          "pip install 'ase-maud[fmm]'") from err
    return lfmm3d


def evaluate(positions: np.ndarray, want_blocks: bool = False,
             fmm_eps: float = 1e-6) -> Result:
    """Unit repulsion by the fast multipole method; see the module docstring.

    Returns ``(energy, forces (N, 3), block6 (N, 6) or None)`` like the
    direct sums (:mod:`.base`). Two points at the same position give ``energy = inf`` and
    NaN forces, as the direct sums do (FMM3D itself would drop that pair);
    points closer than about ``2**-51`` times the scene's size, a few
    rounding errors, are dropped by FMM3D.
    """
    check_eps(fmm_eps)
    lfmm3d = _lfmm3d()
    p = np.asarray(positions, dtype=float)
    n = len(p)
    if n < 2:  # FMM3D gives NaN for a lone point
        return 0.0, np.zeros((n, 3)), np.zeros((n, 6)) if want_blocks else None
    if _has_coincident(p):
        return (np.inf, np.full((n, 3), np.nan),
                np.full((n, 6), np.nan) if want_blocks else None)
    out = lfmm3d(eps=fmm_eps, sources=np.ascontiguousarray(p.T),
                 charges=np.ones(n), pg=3 if want_blocks else 2)
    energy = 0.5 * FMM3D_SCALE * float(out.pot.sum())
    forces = -FMM3D_SCALE * np.ascontiguousarray(out.grad.T)
    block6 = (FMM3D_SCALE * np.ascontiguousarray(out.hess.T) if want_blocks
              else None)
    return energy, forces, block6


def _has_coincident(p):
    """Whether two rows of ``p`` are equal (a sort, O(N log N))."""
    s = p[np.lexsort(p.T)]
    return bool(np.any(np.all(s[1:] == s[:-1], axis=1)))


#: FMM3D's fast multipole method, approximate to ``fmm_eps``.
BACKEND = Backend(
    name='fmm', evaluate=evaluate, cost='N', tolerance='fmm_eps',
    parameters={'fmm_eps': check_eps}, requires=('fmm3dpy',),
    summary="FMM3D's fast multipole method, O(N), approximate to fmm_eps, "
    'parallel over OMP_NUM_THREADS; faster from a few thousand points '
    "(pip install 'ase-maud[fmm]')")
