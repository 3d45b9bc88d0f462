"""Meshes in the formats meshing and CAD tools write: PLY, STL, OFF, VTK and
VTU, read through meshio (the maintained reader and writer of these formats).

The springs are the edges of the faces (triangles, quads, polygons), each
undirected pair once, plus the segments of line cells; coincident points are
merged as in OBJ (:func:`~ase_maud.formats.obj.merge_coincident`: STL stores
every triangle's corners anew). Volume cells (tetrahedra, hexahedra...) are
refused: their edges are no surface net. Written back only as the formats
:mod:`ase_maud.io` writes (OBJ, COMPAS JSON, ...).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import NetData, PathLike
from .obj import merge_coincident

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
    faces, lines = [], []
    for block in mesh.cells:
        if block.type in FACE_CELLS or block.type.startswith('polygon'):
            faces += np.asarray(block.data, dtype=int).tolist()
        elif block.type == 'line':
            lines += np.asarray(block.data, dtype=int).tolist()
        elif block.type != 'vertex':
            raise ValueError(f'{path}: cells of type {block.type!r}; a net is made of '
                             f'faces ({", ".join(FACE_CELLS)}) and lines')
    merged, points = merge_coincident(points)
    faces = [merged[face].tolist() for face in faces]
    pairs = [pair for ring in faces for pair in zip(ring, ring[1:] + ring[:1], strict=True)]
    pairs += [tuple(merged[line].tolist()) for line in lines]
    springs, seen = [], set()
    for i, j in pairs:
        key = (min(i, j), max(i, j))
        if i != j and key not in seen:
            seen.add(key)
            springs.append(key)
    return NetData(points, np.array(springs, dtype=int).reshape(-1, 2), faces, [])
