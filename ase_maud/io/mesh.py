"""Meshes in the formats meshing and CAD tools write: PLY, STL, OFF, VTK and
VTU, read through meshio (the maintained reader and writer of these formats),
but OFF, read here (:func:`read_off`: meshio's reader takes triangles only,
and ends the interpreter on anything else).

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
written with diagonals it does not have. A face index out of
range (negative included) is refused by file and face; a face listed twice
is read once (:func:`ase_maud.io.nets.read_net` says so). Any failure of
meshio, its ``SystemExit`` included, is a ValueError naming the file.
"""

from __future__ import annotations

import contextlib
import io
import re
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
    import meshio  # here: its import costs time every command would pay

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

    if Path(path).suffix.lower() == '.off':
        return read_off(path)
    try:
        with np.errstate(over='ignore'), contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()):
            mesh = meshio.read(path, file_format=MESH_FORMATS[Path(path).suffix.lower()])
    except FileNotFoundError:
        raise
    except (Exception, SystemExit) as error:   # meshio's readers raise many kinds, and exit
        said = f'{type(error).__name__}: {error}' if not isinstance(error, SystemExit) else (
            'its reader gave up on a cell type or layout it does not know: VTK '
            'polylines, strips and pixels, say')
        raise ValueError(f'{path}: meshio cannot read it ({said})') from None
    if mesh.points.ndim != 2 or not len(mesh.points):
        raise ValueError(f'{path}: no points')
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
    for number, block in enumerate(mesh.cells):
        data = np.asarray(block.data, dtype=np.int64)
        if data.size and (data.min() < 0 or data.max() >= len(merged)):
            row = np.flatnonzero(((data < 0) | (data >= len(merged))).any(axis=1))[0]
            raise ValueError(f'{path}: {block.type} {row} of cell block {number} names points '
                             f'{data[row].tolist()}; the file has {len(merged)} points '
                             '(0-based)')
        cells = merged[data]
        if block.type in FACE_CELLS or block.type.startswith('polygon'):
            rings.append(cells)
            pairs.append(face_edges(cells))
        elif block.type == 'line':
            pairs.append(cells)
        elif block.type != 'vertex':
            raise ValueError(f'{path}: cells of type {block.type!r}; a net is made of '
                             f'faces ({", ".join(FACE_CELLS)}) and lines')
    # one block of faces stays one array (a list of lists costs more than the read)
    faces = rings[0] if len(rings) == 1 else [ring for cells in rings for ring in cells.tolist()]
    return _net(points, np.concatenate(pairs), faces)


def _net(points, pairs, faces):
    """The NetData of ``points``, edge ``pairs`` (each kept once, in order)
    and ``faces``."""
    pairs = np.sort(np.asarray(pairs, dtype=int).reshape(-1, 2), axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]   # corners merged into one
    first = np.sort(unique_pairs(pairs)[1])
    return NetData(points, pairs[first], faces, [])


#: OFF headers read by :func:`read_off`: OFF with any of the prefixes ST
#: (texture), C (colours), N (normals) of its vertex lines.
OFF_HEADER = re.compile(r'^(ST)?C?N?OFF$')


def read_off(path: PathLike) -> NetData:
    """Points and faces of an OFF file (``OFF``, ``COFF``, ``NOFF``, ``STOFF``
    ...; faces of any number of corners, a colour after a face's indices
    ignored, as are a vertex line's normal, colour and texture; ``#``
    comments); a ValueError names the file, the line and what was expected."""
    lines = []
    with open(path, encoding='utf-8', errors='replace') as text:
        for number, line in enumerate(text, 1):
            words = line.split('#', 1)[0].split()
            if words:
                lines.append((number, words))
    if not lines or not OFF_HEADER.match(lines[0][1][0]):
        raise ValueError(f'{path}: line {lines[0][0] if lines else 1}: an OFF file starts '
                         "with 'OFF' (or COFF, NOFF, STOFF...); 4OFF, nOFF and binary OFF "
                         'are not read')
    header = lines[0][1][1:] or (lines.pop(1)[1] if len(lines) > 1 else [])
    where = lambda number: f'{path}: line {number}'   # noqa: E731
    try:
        nv, nf = int(header[0]), int(header[1])
    except (IndexError, ValueError):
        raise ValueError(f'{where(lines[0][0])}: expected the counts of vertices, faces '
                         f'and edges, got {" ".join(header)!r}') from None
    if nv < 1 or nf < 0 or len(lines) < 1 + nv + nf:
        raise ValueError(f'{where(lines[0][0])}: {nv} vertices and {nf} faces declared, '
                         f'{len(lines) - 1} lines hold them' if nv >= 1 and nf >= 0 else
                         f'{where(lines[0][0])}: {nv} vertices, {nf} faces')
    points = np.empty((nv, 3))
    for row, (number, words) in enumerate(lines[1:1 + nv]):
        try:
            points[row] = [float(w) for w in words[:3]]
        except ValueError:
            raise ValueError(f'{where(number)}: expected a vertex, three numbers x y z, '
                             f'got {" ".join(words)!r}') from None
        if not np.isfinite(points[row]).all():
            raise ValueError(f'{where(number)}: vertex {row} has a non-finite coordinate')
    merged, points = merge_coincident(points)
    faces, pairs = [], []
    for number, words in lines[1 + nv:1 + nv + nf]:
        try:
            count = int(words[0])
            corners = [int(w) for w in words[1:1 + count]]
        except ValueError:
            raise ValueError(f'{where(number)}: expected a face, a count and as many '
                             f'point indices, got {" ".join(words)!r}') from None
        if count < 2 or len(corners) < count:
            raise ValueError(f'{where(number)}: a face of {count} corners lists '
                             f'{len(corners)}')
        bad = [i for i in corners if not 0 <= i < nv]
        if bad:
            raise ValueError(f'{where(number)}: face index {bad[0]} out of range (the file '
                             f'has {nv} vertices, 0-based)')
        ring = merged[corners].tolist()
        faces.append(ring)
        pairs += zip(ring, ring[1:] + ring[:1], strict=True)
    return _net(points, pairs, faces)
