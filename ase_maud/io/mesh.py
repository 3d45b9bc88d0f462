"""Meshes in the formats meshing and CAD tools write: PLY, STL, OFF, VTK and
VTU, read through meshio (the maintained reader and writer of these formats).

The springs are the edges of the faces (triangles, quads, polygons), each
undirected pair once, plus the segments of line cells; coincident points are
merged as in OBJ (:func:`~ase_maud.io.net_data.merge_coincident`: STL stores
every triangle's corners anew). Volume cells (tetrahedra, hexahedra...) are
refused: their edges are no surface net.

Written back (:func:`write_mesh`) in the format of the file name, with the
faces the net was read with (``atoms.info['faces']``, set by
:func:`~ase_maud.io.nets.read_net`) as triangle, quad and polygon cells and
the springs that are no face's edge as line cells, so that the file read back
is the same net. STL and OFF (as meshio reads it) hold triangles only: a net
with other faces or with lines is refused there, in words, rather than
written with diagonals it does not have.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ase_maud.io.net_data import NetData, PathLike, merge_coincident
from ase_maud.physics.topology import face_edges, unique_pairs

#: Suffixes read by :func:`read_mesh`, and meshio's name of each format.
MESH_FORMATS = {'.ply': 'ply', '.stl': 'stl', '.off': 'off', '.vtk': 'vtk', '.vtu': 'vtu'}

#: meshio cell types whose corners make a ring (a face).
FACE_CELLS = ('triangle', 'quad', 'polygon')

#: Formats that hold triangles only (meshio writes and reads no other cell).
TRIANGLES_ONLY = ('stl', 'off')


def mesh_cells(faces, springs: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """meshio cell blocks of a net: its ``faces`` (rings of point indices,
    a list or an (F, k) array; None or empty: none) by ring size
    (``triangle``, ``quad``, ``polygon``), then its ``springs`` that are no
    face's edge as ``line`` cells."""
    blocks, edges = [], [np.zeros((0, 2), dtype=np.int64)]
    groups = ([np.asarray(faces)] if isinstance(faces, np.ndarray) else
              _by_size(faces or []))
    for ring in groups:
        if len(ring):
            size = ring.shape[1]
            blocks.append(({3: 'triangle', 4: 'quad'}.get(size, 'polygon'), ring))
            edges.append(face_edges(ring))
    springs = np.asarray(springs, dtype=np.int64).reshape(-1, 2)
    both = np.concatenate([*edges, springs])
    inverse = unique_pairs(both)[0]
    in_faces = np.zeros(inverse.max(initial=-1) + 1, dtype=bool)
    in_faces[inverse[:len(both) - len(springs)]] = True
    lines = springs[~in_faces[inverse[len(both) - len(springs):]]]
    if len(lines):
        blocks.append(('line', lines))
    return blocks


def _by_size(faces) -> list[np.ndarray]:
    by_size: dict[int, list] = {}
    for face in faces:
        by_size.setdefault(len(face), []).append(face)
    return [np.asarray(rings, dtype=np.int64) for rings in by_size.values()]


def write_mesh(path: PathLike, positions: np.ndarray, faces, springs: np.ndarray) -> None:
    """Write a net (``positions`` (N, 3), ``faces`` as :func:`mesh_cells`
    takes them, ``springs`` (K, 2)) to ``path`` by meshio in the format of
    its suffix (:data:`MESH_FORMATS`); the file replaced whole. A ValueError
    for a format that cannot hold the net (see the module docstring)."""
    import meshio

    from ase_maud.files.atomic_replace import replace_with

    path = Path(path)
    kind = MESH_FORMATS[path.suffix.lower()]
    blocks = mesh_cells(faces, springs)
    if kind in TRIANGLES_ONLY:
        other = sorted({name for name, _ in blocks if name != 'triangle'})
        if other or not blocks:
            held = (f'{", ".join(other)} cells' if other else
                    'no faces (a network: its springs are lines)')
            raise ValueError(f'cannot write {path.name}: {kind.upper()} holds triangles '
                             f'only, and the net has {held}; write .ply, .vtk, .vtu or '
                             '.obj, which keep them')
    if kind == 'ply':   # PLY's indices are 32-bit; meshio casts with a warning
        blocks = [(name, cells.astype(np.int32)) for name, cells in blocks]
    mesh = meshio.Mesh(np.asarray(positions, dtype=float), blocks)
    replace_with(path, lambda temporary: meshio.write(temporary, mesh, file_format=kind))


def read_mesh(path: PathLike) -> NetData:
    """Points, springs and faces of a mesh file of :data:`MESH_FORMATS` (see
    the module docstring); a ValueError names the file and what is wrong."""
    import meshio  # imported here: its import costs time every command would pay

    try:
        with np.errstate(over='ignore'):   # meshio's test for binary STL on a text file
            mesh = meshio.read(path, file_format=MESH_FORMATS[Path(path).suffix.lower()])
    except FileNotFoundError:
        raise
    except Exception as error:   # meshio's readers raise many kinds
        raise ValueError(f'{path}: meshio cannot read it ({type(error).__name__}: '
                         f'{error})') from error
    points = np.zeros((len(mesh.points), 3))
    points[:, :mesh.points.shape[1]] = mesh.points
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        raise ValueError(f'{path}: point {bad[0]} has a non-finite coordinate '
                         f'{points[bad[0]].tolist()}')
    if not len(points):
        raise ValueError(f'{path}: no points')
    rings, pairs = [], [np.zeros((0, 2), dtype=int)]
    merged, points = merge_coincident(points)
    for block in mesh.cells:
        cells = merged[np.asarray(block.data, dtype=int)]
        if block.type in FACE_CELLS or block.type.startswith('polygon'):
            rings.append(cells)
            pairs.append(face_edges(cells))
        elif block.type == 'line':
            pairs.append(cells)
        elif block.type != 'vertex':
            raise ValueError(f'{path}: cells of type {block.type!r}; a net is made of '
                             f'faces ({", ".join(FACE_CELLS)}) and lines')
    pairs = np.sort(np.concatenate(pairs), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]   # corners merged into one
    first = np.sort(unique_pairs(pairs)[1])
    # one block of faces stays one array (a list of lists costs more than the read)
    faces = rings[0] if len(rings) == 1 else [ring for cells in rings for ring in cells.tolist()]
    return NetData(points, pairs[first], faces, [])
