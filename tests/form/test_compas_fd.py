"""A peer: compas_fd's linear force-density solver on compas's sample meshes.

With springs ``Q q_s L**2 / 2`` a net pulls along each edge with ``Q q_s L``:
compas_fd's force density is ``Q q_s``. At ``a = 1e-4`` times the mean edge the
repulsion ``a**3 Q / L`` moves the equilibrium by about ``(a / edge)**3`` of
the edge, 1e-12: Maud's minimum is ``fd_numpy``'s solution.
"""

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.io.nets import read_net

compas = pytest.importorskip('compas')
fd_numpy = pytest.importorskip('compas_fd.solvers').fd_numpy

MESHES = ('faces.obj', 'hypar.obj', 'quadmesh.obj')
#: Maud's repulsion length, in mean edges.
A_PER_EDGE = 1e-4
#: The largest gap allowed, in units of the mesh's size (its box's diagonal).
GAP = 1e-9


def boundary_vertices(path):
    """0-based indices of the vertices on an edge of one face only (OBJ
    ``f`` lines; ``v/vt/vn`` indices, 1-based or negative)."""
    count, faces = 0, []
    with open(path) as f:
        for line in f:
            tokens = line.split()
            if tokens and tokens[0] == 'v':
                count += 1
            elif tokens and tokens[0] == 'f':
                faces.append([int(t.split('/')[0]) for t in tokens[1:]])
    edges = {}
    for face in faces:
        ring = [i - 1 if i > 0 else count + i for i in face]
        for i, j in zip(ring, ring[1:] + ring[:1], strict=True):
            key = (min(i, j), max(i, j))
            edges[key] = edges.get(key, 0) + 1
    return sorted({i for edge, faces in edges.items() if faces == 1 for i in edge})


@pytest.mark.parametrize('loaded', [False, True])
@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('name', MESHES)
def test_maud_at_a_small_a_is_the_force_density_solution(name, seed, loaded):
    path = compas.get(name)
    fixed = boundary_vertices(path)
    atoms = read_net(path, fixed=fixed, dim=3)
    springs, start = atoms.calc.springs, atoms.positions.copy()
    edge = np.linalg.norm(start[springs[:, 0]] - start[springs[:, 1]], axis=1).mean()
    size = np.linalg.norm(np.ptp(start, axis=0))
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.5, 2.0, len(springs))
    loads = np.zeros_like(start)
    if loaded:
        free = np.setdiff1d(np.arange(len(atoms)), fixed)
        loads[free] = rng.normal(0.0, 0.3 * edge, (len(free), 3))
    atoms.calc.set(a=A_PER_EDGE * edge, q=q, loads=loads)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-11 * edge, steps=200)
    peer = fd_numpy(vertices=start.tolist(), fixed=fixed, edges=springs.tolist(),
                    forcedensities=q.tolist(), loads=loads.tolist())
    gap = np.abs(atoms.positions - np.asarray(peer.vertices)).max()
    print(f'{name} seed {seed} loaded {loaded}: {len(atoms)} points, {opt.nsteps} steps, '
          f'gap {gap / size:.1e} of the size')
    assert gap <= GAP * size
    # the peer and Maud both moved the net: the comparison can fail
    assert np.abs(atoms.positions - start).max() > 1e3 * GAP * size
