"""Meshes in the formats meshing and CAD tools write: PLY, STL, OFF, VTK and
VTU, read through meshio (the maintained reader and writer of these formats).

The springs are the edges of the faces (triangles, quads, polygons), each
undirected pair once, plus the segments of line cells; coincident points are
merged as in OBJ (:func:`~ase_maud.io.obj.merge_coincident`: STL stores
every triangle's corners anew). Volume cells (tetrahedra, hexahedra...) are
refused: their edges are no surface net. Written back only as the formats
:mod:`ase_maud.io` writes (OBJ, COMPAS JSON, ...).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ase_maud.io.net_data import NetData, PathLike
from ase_maud.io.obj import merge_coincident

#: Suffixes read by :func:`read_mesh`, and meshio's name of each format.
MESH_FORMATS = {'.ply': 'ply', '.stl': 'stl', '.off': 'off', '.vtk': 'vtk', '.vtu': 'vtu'}

#: meshio cell types whose corners make a ring (a face).
FACE_CELLS = ('triangle', 'quad', 'polygon')


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
    faces, pairs = [], [np.zeros((0, 2), dtype=int)]
    merged, points = merge_coincident(points)
    for block in mesh.cells:
        cells = merged[np.asarray(block.data, dtype=int)]
        if block.type in FACE_CELLS or block.type.startswith('polygon'):
            faces += cells.tolist()
            pairs.append(np.stack([cells, np.roll(cells, -1, axis=1)], axis=-1).reshape(-1, 2))
        elif block.type == 'line':
            pairs.append(cells)
        elif block.type != 'vertex':
            raise ValueError(f'{path}: cells of type {block.type!r}; a net is made of '
                             f'faces ({", ".join(FACE_CELLS)}) and lines')
    pairs = np.sort(np.concatenate(pairs), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]   # corners merged into one
    first = np.sort(np.unique(pairs, axis=0, return_index=True)[1])
    return NetData(points, pairs[first], faces, [])
