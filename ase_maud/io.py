"""Nets from files and back: points, springs, and the Maud parameters.

:func:`read_net` returns an :class:`ase.Atoms` (``pbc=False``) with a
:class:`~ase_maud.MaudCalculator` attached; its ``calc.springs`` are the
file's edges. :func:`write_net` writes a (relaxed) net back, in the format
its file name says, keeping the rest of an original file (``like=``).

Formats, chosen by the file name's suffix:

- ``.obj``, Wavefront OBJ: each ``v`` line is a point, coincident ones
  merged (:func:`merge_coincident`); the springs are the edges of the faces
  (``f``), each undirected edge once, plus the segments of the polylines
  (``l``) and of the curves of degree 1 (``cstype bspline`` or ``bezier``,
  ``deg 1``, ``curv u0 u1 v1 v2 ...``: Rhino's line export). Indices may be
  ``v``, ``v/vt``, ``v//vn``, ``v/vt/vn``, 1-based or negative (relative).
  Other statements (``vn``, ``vt``, ``g``, ``o``, ``usemtl``, ``parm``,
  ``end``, ...) are kept on writing and ignored on reading.
- ``.json``, COMPAS data: a mesh (``vertex`` and ``face`` dicts; springs are
  the faces' edges) or a network/graph (``node`` and ``edge`` dicts; springs
  are the edges), bare or in COMPAS's envelope (``{"dtype": ..., "value":
  {...}}`` of COMPAS 1.x, ``{"dtype": ..., "data": {...}}`` of 2.x). Points
  are in the order of the file's vertex (node) keys; a vertex attribute
  ``is_anchor`` or ``is_fixed`` that is true fixes the point. As in
  compas_fd, an edge attribute ``q`` is the spring's force density (the
  calculator's ``q``, a multiplier of ``Q``: ``Q q`` with ``Q = 1``) and
  vertex attributes ``px``, ``py``, ``pz`` its load (the calculator's
  ``loads``), each from the item's own attributes, else the file's
  defaults, else 1 and 0. Written back as the original structure with
  ``x``, ``y``, ``z`` replaced, and ``q``, ``px``, ``py``, ``pz`` set
  where the net's differ from the file's.
- ``.traj``, ASE trajectory: the springs, ``a``, ``Q``, ``dim``, ``q`` and
  ``loads`` come back
  from the calculator parameters that ASE's trajectory stores with every
  frame (:meth:`MaudCalculator.todict`), the fixed points from its
  constraints.
- anything else ASE reads (extended XYZ, ...), plus an edge list: a text
  file of two 0-based point indices per line, ``#`` comments allowed. By
  default ``NAME.edges.txt`` beside ``NAME.xyz``; :func:`write_net` writes it
  there.

Written back (``like=``), an OBJ or JSON file keeps its text but for the
coordinates that moved, each written as the shortest text that reads back as
its float (``repr``); line endings, comments and every other line as read.

Reader choice: our own OBJ parser. meshio's OBJ reader skips
``l`` lines and reports no line numbers; trimesh triangulates quads, adding
a diagonal spring to every quad. Neither keeps the rest of the file for
writing back. COMPAS's JSON is plain JSON: the standard library reads it.

Malformed input is a ValueError naming the file, the line (where the format
has lines) and what was expected.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import uuid
from collections.abc import Iterator, Sequence
from io import StringIO
from pathlib import Path
from typing import Any, NamedTuple

import ase.io
import ase.io.formats
import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from scipy.spatial import cKDTree

from .atomic import replace_text, replace_with
from .calculator import MaudCalculator
from .checks import as_whole, check, check_writable
from .scenes import keep_on_plane
from .topology import (
    boundary_vertices,
    fixed_atoms,
    free_point_loads,
    leaf_vertices,
    spring_components,
)

PathLike = str | os.PathLike
#: The name under which ASE's trajectory stores a MaudCalculator.
CALC_NAME = 'maudcalculator'
#: Vertex (node) attributes of COMPAS data that fix a point when true.
ANCHOR_ATTRIBUTES = ('is_anchor', 'is_fixed')
#: The longest line a text file (OBJ, edge list, indices) may have, in
#: characters: what is read of one line at a time (memory stays bounded).
MAX_LINE = 1_000_000
#: Vertex (node) attributes of COMPAS data that hold a load (compas_fd's).
LOAD_ATTRIBUTES = ('px', 'py', 'pz')
#: OBJ vertices closer than this times the diagonal of their bounding box
#: are one point (a Rhino export gives every curve its own copies of its
#: end vertices).
MERGE_TOLERANCE = 1e-9
#: OBJ curve types (``cstype``, after an optional ``rat``) read, with
#: ``deg 1``: polylines through their control points.
CURVE_TYPES = ('bspline', 'bezier')
#: The rules ``fixed=`` takes by name (:func:`read_net`).
FIX_RULES = ('boundary', 'leaves')
#: ``a`` of a net read from a file that stores none, as a fraction of its
#: mean spring length (:func:`default_a`; tools/a_rule.py measures it).
A_PER_MEAN_SPRING = 0.3


class NetData(NamedTuple):
    """What a mesh or network file holds."""
    positions: np.ndarray     #: (N, 3) points
    springs: np.ndarray       #: (K, 2) 0-based point pairs, each once
    faces: list[list[int]]    #: rings of point indices; [] for a network
    anchors: list[int]        #: points the file marks fixed


def mean_spring_length(positions: np.ndarray, springs: np.ndarray) -> float:
    """The mean length of the springs, in the positions' unit."""
    i, j = np.asarray(springs, dtype=int).reshape(-1, 2).T
    return float(np.linalg.norm(positions[i] - positions[j], axis=1).mean())


def default_a(positions: np.ndarray, springs: np.ndarray) -> float:
    """``a`` of a net that comes without one: :data:`A_PER_MEAN_SPRING`
    times its mean spring length. The largest fraction of 0.1, 0.2, 0.3,
    0.4, 0.5, 0.7, 1 with which each of ten compas sample nets (32 to 4900
    points), its boundary (leaves) fixed, relaxes within the bounding box of
    its supports (docs/bench/a_rule.md); at 0.4 the largest ones reach out
    of it (the repulsion of many points adds up), at 1 most balloon.
    """
    return A_PER_MEAN_SPRING * mean_spring_length(positions, springs)


def net_format(path: PathLike) -> str:
    """'obj', 'json', 'traj' or 'ase' (any other file ASE reads), by suffix."""
    suffix = Path(path).suffix.lower()
    return {'.obj': 'obj', '.json': 'json', '.traj': 'traj'}.get(suffix, 'ase')


def check_net_path(name: str, path: PathLike) -> Path:
    """``path`` checked as a file :func:`write_net` can write, before any
    work: a writable file (:func:`~ase_maud.checks.check_writable`) whose
    suffix names a format (one of :func:`net_format`'s, or one ASE writes);
    else a ValueError naming ``name``, the file and what is accepted."""
    path = check_writable(name, path)
    if net_format(path) == 'ase' and path.suffix.lower() not in ('.xyz', '.extxyz'):
        try:
            known = ase.io.formats.ioformats[ase.io.formats.filetype(path, read=False)]
        except (KeyError, ase.io.formats.UnknownFileTypeError):
            known = None
        if known is None or not known.can_write:
            raise ValueError(f'{name} {str(path)!r}: no net format has the suffix '
                             f'{path.suffix!r}; use .obj, .json, .traj, .xyz or another '
                             'format ASE writes')
    return path


def relaxed_fmax(path: PathLike) -> float | None:
    """The fmax an ASE trajectory was relaxed to (the ``fmax`` its
    optimizer stored in the trajectory's description; force units), or None
    for other files and for trajectories that do not say."""
    if net_format(path) != 'traj':
        return None
    from ase.io.trajectory import Trajectory
    with Trajectory(path) as frames:
        fmax = (frames.description or {}).get('fmax')
    return None if fmax is None else float(fmax)


def edges_path(path: PathLike) -> Path:
    """The default edge list of a point file: ``NAME.edges.txt`` beside it."""
    path = Path(path)
    return path.with_name(path.stem + '.edges.txt')


def read_net(path: PathLike, edges: PathLike | None = None,
             fixed: PathLike | Sequence[int] | None = None,
             a: float | None = None, Q: float | None = None,
             dim: int | None = None, index: int = -1,
             load: Sequence[float] | None = None) -> Atoms:
    """Read a net: an Atoms with a MaudCalculator attached.

    Parameters
    ----------
    path : file name
        OBJ, COMPAS JSON, ASE trajectory or any file ASE reads (see the
        module docstring).
    edges : file name, optional
        Edge list (two 0-based indices per line); overrides the springs a
        file holds. Default for point files: ``NAME.edges.txt`` if present.
    fixed : 'boundary', 'leaves', file name or indices, optional
        Points held fixed (:class:`FixAtoms`), replacing the constraints
        read from the file: ``'boundary'``, the boundary of a mesh's faces
        (:func:`~ase_maud.topology.boundary_vertices`; OBJ and COMPAS
        meshes); ``'leaves'``, the points on one spring
        (:func:`~ase_maud.topology.leaf_vertices`); a file of 0-based
        indices, one or more per line (a ``Path`` is always a file); or the
        indices.
    a, Q : float, optional
        Length and spring constant of the potential. Default ``a``: what a
        trajectory stores (1 if it stores its calculator without ``a``),
        else :func:`default_a` of the net; ``Q``: what a trajectory
        stores, else 1.
    dim : 2 or 3, optional
        Default: what a trajectory stores, else 2 if every point has the
        same z and no load has a z component, else 3.
    index : int
        The frame of a trajectory (or multi-frame file), default the last.
    load : (3,) floats, optional
        A constant load (force units) on every free point
        (:func:`free_point_loads`; self-weight, say), replacing the loads
        the file holds.
    """
    return _read(path, edges, fixed, a, Q, dim, index, load)[0]


def read_frames(path: PathLike, edges: PathLike | None = None,
                fixed: PathLike | Sequence[int] | None = None,
                a: float | None = None, Q: float | None = None,
                dim: int | None = None,
                load: Sequence[float] | None = None) -> list[Atoms]:
    """Every frame of a file (one for OBJ and JSON), as :func:`read_net`."""
    return _read(path, edges, fixed, a, Q, dim, slice(None), load)


def _read(path, edges, fixed, a, Q, dim, index, load=None):
    """Frames of ``path`` with their calculators, as :func:`read_net` says."""
    if Path(path).is_dir():
        raise ValueError(f'{path} is a directory, not a net file')
    kind = net_format(path)
    faces = []
    if kind in ('obj', 'json'):
        positions, springs, faces, anchors = (read_obj(path) if kind == 'obj'
                                              else read_compas(path))
        frames = [Atoms(positions=positions, pbc=False)]
        if len(anchors):
            frames[0].set_constraint(FixAtoms(indices=anchors))
        stored = {'springs': springs} if len(springs) else {}
        if kind == 'json':
            stored.update(read_compas_forces(path, springs))
    else:
        frames, stored = _read_ase(path, index)
    natoms = len(frames[0])
    if edges is None and 'springs' not in stored and edges_path(path).exists():
        edges = edges_path(path)
    if edges is not None:
        stored['springs'] = read_edges(edges, natoms)
        stored.pop('q', None)   # the file's force densities are of its own springs
    if 'springs' not in stored:
        raise ValueError(f'{path} holds no springs: give an edge list '
                         f'(edges=..., --edges, or {edges_path(path).name} '
                         'beside it)')
    if a is None and 'a' not in stored:
        a = default_a(frames[0].positions, stored['springs'])
    given = {'a': a, 'Q': Q, 'dim': dim}
    parameters = {**stored, **{k: v for k, v in given.items() if v is not None}}
    if fixed is not None:
        indices = _fixed_points(path, fixed, natoms, stored['springs'], faces)
    for atoms in frames:
        atoms.pbc = False
        if fixed is not None:
            atoms.set_constraint(FixAtoms(indices=indices))
        own = dict(parameters)
        if load is not None:
            own['loads'] = free_point_loads(atoms, load)
        z = atoms.positions[:, 2]
        loads = own.get('loads')
        flat = np.all(z == z[:1]) and (loads is None or not np.any(np.asarray(loads)[:, 2:]))
        atoms.calc = MaudCalculator(**{'dim': 2 if flat else 3, **own})
        if atoms.calc.dim == 2:
            keep_on_plane(atoms)   # ASE's own drivers move z otherwise
    return frames


def _fixed_points(path, fixed, natoms, springs, faces):
    """The indices ``fixed=`` names (:func:`read_net`), checked."""
    if isinstance(fixed, str) and fixed in FIX_RULES:
        if fixed == 'boundary' and not faces:
            raise ValueError(f"{path}: fixed='boundary' needs a mesh's faces and the "
                             "file has none (OBJ 'f' lines or a COMPAS mesh); "
                             "'leaves' fixes the ends of a network's lines")
        indices = (boundary_vertices(faces) if fixed == 'boundary'
                   else leaf_vertices(natoms, springs))
        if not len(indices):
            raise ValueError(f"{path}: fixed={fixed!r} finds no point (" + (
                'every edge is in two faces: a closed mesh' if fixed == 'boundary'
                else "no point is on exactly one spring; 'boundary' fixes a mesh's")
                + '); name the fixed points')
        return indices.tolist()
    if isinstance(fixed, str) and not Path(fixed).exists():
        raise ValueError(f'fixed={fixed!r} is neither a rule ({", ".join(FIX_RULES)}) '
                         'nor a file')
    if isinstance(fixed, (str, os.PathLike)):
        return read_indices(fixed, natoms)
    return _fixed_indices(fixed, natoms)


def stored_parameters(frame: Atoms) -> dict[str, Any]:
    """The MaudCalculator parameters a frame read from a file stores with
    its energy and forces (an ASE trajectory does), or {}."""
    calc = frame.calc
    if calc is None or getattr(calc, 'name', '') != CALC_NAME:
        return {}
    return {k: v for k, v in calc.parameters.items()
            if k in MaudCalculator.default_parameters}


def _read_ase(path, index):
    """Frames of an ASE-readable file, and the MaudCalculator parameters its
    (first) frame stores, if any."""
    try:
        frames = ase.io.read(path, index)
    except FileNotFoundError:
        raise
    except Exception as error:   # ASE's readers raise many kinds
        raise ValueError(f'{path}: ASE cannot read it ({type(error).__name__}: '
                         f'{error})') from error
    frames = frames if isinstance(frames, list) else [frames]
    if not frames:
        raise ValueError(f'{path}: no frame at index {index}')
    stored = stored_parameters(frames[0])
    if stored:   # a calculator stored without a has the default a
        stored.setdefault('a', MaudCalculator.default_parameters['a'])
    for atoms in frames:
        atoms.calc = None
    return frames, stored


def _lines(path: PathLike) -> Iterator[tuple[int, list[str]]]:
    """(line number, tokens) of every line with tokens, ``#`` comments cut;
    a UTF-8 byte-order mark is skipped, other bytes than UTF-8 text are a
    ValueError naming the line."""
    number = 0
    try:
        with open(path, encoding='utf-8-sig') as f:
            while (line := f.readline(MAX_LINE + 1)):
                number += 1
                if len(line) > MAX_LINE:
                    raise ValueError(f'{path} line {number}: longer than {MAX_LINE} '
                                     'characters (not a text file of points, lines or '
                                     'indices?)')
                tokens = line.split('#', 1)[0].split()
                if tokens:
                    yield number, tokens
    except UnicodeDecodeError:
        raise ValueError(f'{path} line {number + 1} or near it: not UTF-8 text') from None


def _finite(path, where, values):
    """``values`` (floats), or ValueError naming ``where`` if one is not
    finite (nan, inf, or beyond the float64 range such as 1e400)."""
    if not np.isfinite(values).all():
        raise ValueError(f'{path} {where}: coordinates must be finite numbers, got '
                         f'{values}')
    return values


def _numbers(path, number, tokens, what, kind=int):
    """``tokens`` as ``kind`` (int or float), or ValueError naming the line
    and ``what``."""
    try:
        return [kind(t) for t in tokens]
    except ValueError:
        raise ValueError(f'{path} line {number}: expected {what}, got '
                         f'{" ".join(tokens)!r}') from None


def _check_index(path, number, i, natoms):
    if not 0 <= i < natoms:
        raise ValueError(f'{path} line {number}: index {i} out of range '
                         f'({natoms} points, 0-based)')


def _fixed_indices(indices, natoms):
    """``indices`` as a list of ints in ``range(natoms)``, or ValueError."""
    checked = [as_whole(i) for i in indices]
    for given, i in zip(indices, checked, strict=True):
        if i is None:
            raise ValueError(f'fixed point {given!r} is not a whole number (0-based index)')
        if not 0 <= i < natoms:
            raise ValueError(f'fixed point {i} out of range ({natoms} points, 0-based)')
    return checked


def read_edges(path: PathLike, natoms: int) -> np.ndarray:
    """An edge list: (K, 2) int array from two 0-based indices per line.

    ValueError with the line number on anything else, an index out of
    ``range(natoms)``, a spring from a point to itself or a repeated pair.
    """
    springs, seen = [], {}
    for number, tokens in _lines(path):
        pair = _numbers(path, number, tokens, 'two integer indices')
        if len(pair) != 2:
            raise ValueError(f'{path} line {number}: expected two integer '
                             f'indices, got {len(pair)}')
        for i in pair:
            _check_index(path, number, i, natoms)
        key = tuple(sorted(pair))
        if key[0] == key[1]:
            raise ValueError(f'{path} line {number}: spring ties point '
                             f'{key[0]} to itself')
        if key in seen:
            raise ValueError(f'{path} line {number}: spring {key} repeats '
                             f'line {seen[key]}')
        seen[key] = number
        springs.append(pair)
    return np.array(springs, dtype=int).reshape(-1, 2)


def read_indices(path: PathLike, natoms: int) -> list[int]:
    """0-based point indices, one or more per line (``#`` comments allowed);
    ValueError with the line number on a non-integer or out of range."""
    indices = []
    for number, tokens in _lines(path):
        for i in _numbers(path, number, tokens, 'integer point indices'):
            _check_index(path, number, i, natoms)
            indices.append(i)
    return indices


def read_obj(path: PathLike) -> NetData:
    """Points, springs and faces of an OBJ file (see the module docstring).

    Springs: the edges of every face (``f``), the segments of every polyline
    (``l``) and of every curve of degree 1 (``curv``), each undirected pair
    once, in order of appearance. Vertices closer than
    :data:`MERGE_TOLERANCE` times the diagonal of their bounding box are one
    point (:func:`merge_coincident`).
    """
    return _obj_file(path)[0]


def merge_coincident(points: np.ndarray,
                     tolerance: float = MERGE_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """The point of every one of (N, 3) ``points`` once coincident ones are
    merged, and the merged points.

    Two points closer than ``tolerance`` times the diagonal of the points'
    bounding box are one (and so, in a chain, are all points linked by such
    pairs); a merged point sits where its first copy does, and merged points
    are in the order of their first copies.
    """
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    pairs = cKDTree(points).query_pairs(tolerance * diagonal, output_type='ndarray')
    labels = spring_components(len(points), pairs)
    first = np.full(labels.max() + 1, len(points))
    np.minimum.at(first, labels, np.arange(len(points)))
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[labels], points[first[order]]


def _statements(path):
    """(line number, tokens) of an OBJ file's statements; a line that ends
    in a backslash goes on in the next (numbered as its first line)."""
    held = None
    for number, tokens in _lines(path):
        if held is not None:
            number, tokens = held[0], held[1] + tokens
        held = None
        if tokens[-1].endswith('\\'):
            tokens[-1] = tokens[-1][:-1]
            held = (number, [t for t in tokens if t])
        else:
            yield number, tokens
    if held is not None and held[1]:
        yield held


def _curve_indices(path, number, rest, curve):
    """The control points' raw indices of ``curv u0 u1 v1 v2 ...``, if the
    curve (``cstype`` and ``deg`` before it) is a polyline; else ValueError."""
    kind, degree = curve
    if degree is None or kind is None:
        raise ValueError(f"{path} line {number}: a 'curv' needs 'cstype' and 'deg' "
                         'statements before it')
    if kind not in CURVE_TYPES or degree != 1:
        raise ValueError(f"{path} line {number}: a curve of type {kind!r} and degree "
                         f'{degree}; only polylines (cstype bspline or bezier, deg 1) '
                         'are read')
    _numbers(path, number, rest[:2], "'curv u0 u1 v1 v2 ...' with numbers u0 u1", float)
    if len(rest) < 4:
        raise ValueError(f"{path} line {number}: a 'curv' needs its parameters u0 u1 "
                         f'and at least 2 vertex indices, got {len(rest)} numbers')
    return rest[2:]


def _obj_file(path):
    """The net of an OBJ file (:class:`NetData`), the point of every ``v``
    statement (:func:`merge_coincident`) and the line numbers of the ``v``
    statements."""
    vertices, rows, refs = [], [], []   # refs: (line, element kind, 0-based indices)
    curve = (None, None)   # cstype and deg of the curves that follow
    for number, tokens in _statements(path):
        keyword, rest = tokens[0], tokens[1:]
        if keyword == 'v':
            xyz = _numbers(path, number, rest[:3], "'v x y z' with numbers", float)
            if len(rest) < 3:
                raise ValueError(f"{path} line {number}: expected 'v x y z', "
                                 f'got {len(rest)} coordinates')
            vertices.append(_finite(path, f'line {number}', xyz))
            rows.append(number)
        elif keyword == 'cstype':
            curve = (rest[-1] if rest else '', curve[1])
        elif keyword == 'deg':
            curve = (curve[0], _numbers(path, number, rest[:1] or ['?'], 'a degree')[0])
        elif keyword in ('f', 'l', 'curv'):
            least = 3 if keyword == 'f' else 2
            if keyword == 'curv':
                rest = _curve_indices(path, number, rest, curve)
            if len(rest) < least:
                raise ValueError(f'{path} line {number}: a {keyword!r} needs '
                                 f'at least {least} vertex indices, got {len(rest)}')
            raw = _numbers(path, number, [t.split('/')[0] for t in rest],
                           'integer vertex indices (v, v/vt, v//vn or v/vt/vn)')
            if 0 in raw:
                raise ValueError(f'{path} line {number}: vertex index 0 (OBJ '
                                 'counts from 1)')
            # negative indices count back from the last vertex read so far
            refs.append((number, keyword,
                         [i - 1 if i > 0 else len(vertices) + i for i in raw]))
    if not vertices:
        raise ValueError(f"{path}: no vertices ('v x y z' lines)")
    point_of, points = merge_coincident(np.array(vertices, dtype=float))
    springs, seen, faces = [], set(), []
    for number, keyword, indices in refs:
        for i in indices:
            if not 0 <= i < len(vertices):
                one_based = i + 1 if i >= 0 else i - len(vertices)
                kind = {'f': 'face', 'l': 'line', 'curv': 'curve'}[keyword]
                raise ValueError(f'{path} line {number}: {kind} index '
                                 f'{one_based} out of range ({len(vertices)} vertices)')
        ring = indices + indices[:1] if keyword == 'f' else indices
        for i, j in zip(ring[:-1], ring[1:], strict=True):
            if point_of[i] == point_of[j]:
                same = ('repeats next to itself' if i == j else
                        f'and vertex {j + 1} next to it are one point (closer than '
                        f'{MERGE_TOLERANCE:g} of the net\'s size)')
                raise ValueError(f'{path} line {number}: vertex {i + 1} {same}: a '
                                 'spring from a point to itself')
            p, q = int(point_of[i]), int(point_of[j])
            if (key := (min(p, q), max(p, q))) not in seen:
                seen.add(key)
                springs.append((p, q))
        if keyword == 'f':
            faces.append(point_of[indices].tolist())
    net = NetData(points, np.array(springs, dtype=int).reshape(-1, 2), faces, [])
    return net, point_of, rows


def _compas_data(path: PathLike, number=None) -> tuple[Any, dict[str, Any]]:
    """The whole JSON document of a COMPAS file and its data dict;
    ``number(text)`` makes every number if given."""
    def unique_keys(pairs):
        keys = [key for key, _ in pairs]
        if len(set(keys)) < len(keys):
            twice = next(key for key in keys if keys.count(key) > 1)
            raise ValueError(f'{path}: key {twice!r} appears twice in one object '
                             '(JSON keeps only the last; name each vertex once)')
        return dict(pairs)

    try:
        with open(path, encoding='utf-8-sig', newline='') as f:
            document = json.load(f, object_pairs_hook=unique_keys,
                                 parse_float=number, parse_int=number)
    except json.JSONDecodeError as error:
        raise ValueError(f'{path} line {error.lineno}: not valid JSON '
                         f'({error.msg})') from None
    except UnicodeDecodeError:
        raise ValueError(f'{path}: not UTF-8 text') from None
    except RecursionError:
        raise ValueError(f'{path}: nested too deeply for a JSON reader (not a COMPAS '
                         'file)') from None
    except MemoryError:
        raise ValueError(f'{path}: too large to read into memory '
                         f'({os.path.getsize(path)} bytes)') from None
    except ValueError as error:   # an integer of more than 4300 digits, say
        if str(error).startswith(str(path)):
            raise
        raise ValueError(f'{path}: {error}') from None
    data = document
    if isinstance(data, dict) and 'dtype' in data:
        data = data.get('data', data.get('value'))
    if not isinstance(data, dict) or not ({'vertex', 'face'} <= data.keys()
                                          or 'node' in data):
        raise ValueError(f'{path}: expected COMPAS mesh data ("vertex" and '
                         '"face") or network data ("node" and "edge"), bare or '
                         'in {"dtype": ..., "data"/"value": ...}')
    _check_structure(path, data)
    return document, data


#: The JSON type of each part of COMPAS data, and of each of its values.
COMPAS_PARTS = {'vertex': (dict, object), 'node': (dict, object), 'face': (dict, list),
                'edge': (dict, (dict, type(None))), 'edgedata': (dict, dict),
                'default_vertex_attributes': (dict, object), 'dva': (dict, object),
                'default_node_attributes': (dict, object), 'dna': (dict, object),
                'default_edge_attributes': (dict, object), 'dea': (dict, object)}


def _check_structure(path: PathLike, data: dict[str, Any]) -> None:
    """ValueError naming the part of COMPAS ``data`` that is not the JSON
    type :data:`COMPAS_PARTS` says (a list where an object belongs, say)."""
    names = {dict: 'an object', list: 'a list', object: 'a value',
             (dict, type(None)): 'an object'}
    for part, (kind, item) in COMPAS_PARTS.items():
        value = data.get(part)
        if value is None:
            continue
        if not isinstance(value, kind):
            raise ValueError(f'{path}: "{part}" must be {names[kind]}, got '
                             f'{type(value).__name__}')
        for key, entry in value.items():
            if not isinstance(entry, item):
                raise ValueError(f'{path}: "{part}" entry {key!r} must be {names[item]}, '
                                 f'got {entry!r}'[:300])


def _compas_points(path, data):
    """The points' dict (vertex or node) and default attributes of ``data``."""
    if 'face' in data:
        return data['vertex'], data.get('default_vertex_attributes', data.get('dva', {}))
    return data['node'], data.get('default_node_attributes', data.get('dna', {}))


def read_compas(path: PathLike) -> NetData:
    """Points, springs, faces and anchors of a COMPAS mesh or network JSON
    file (see the module docstring)."""
    _, data = _compas_data(path)
    points, defaults = _compas_points(path, data)
    if not isinstance(points, dict) or not points:
        raise ValueError(f'{path}: no vertices (nodes)')
    keys = {str(k): n for n, k in enumerate(points)}
    positions, anchors = [], []
    for key, attributes in points.items():
        if not isinstance(attributes, dict):
            raise ValueError(f'{path}: vertex {key} is {attributes!r}, not an object '
                             'of attributes ({"x": ..., "y": ..., "z": ...})')
        xyz = []
        for axis in 'xyz':
            value = attributes.get(axis, defaults.get(axis))
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise ValueError(f'{path}: vertex {key} has no number {axis} '
                                 f'(got {value!r})')
            xyz.append(float(value))
        positions.append(_finite(path, f'vertex {key}', xyz))
        flags = [attributes.get(name, defaults.get(name)) for name in ANCHOR_ATTRIBUTES]
        for name, flag in zip(ANCHOR_ATTRIBUTES, flags, strict=True):
            if flag is not None and not isinstance(flag, bool) and flag not in (0, 1):
                raise ValueError(f'{path}: vertex {key} has {name} = {flag!r}; '
                                 'expected true or false')
        if any(flags):
            anchors.append(keys[key])

    def index(key, where):
        name = str(key)   # 2.x faces hold int keys, everything else strings
        if name not in keys:
            raise ValueError(f'{path}: {where} names vertex {key!r}, which is '
                             'not in the vertex (node) dict')
        return keys[name]

    faces = [[index(v, f'face {fkey}') for v in vertices]
             for fkey, vertices in data.get('face', {}).items()]
    if 'face' in data:
        pairs = [pair for ring in faces for pair in zip(ring, ring[1:] + ring[:1], strict=True)]
    else:
        pairs = [(index(u, f'edge {u}-{v}'), index(v, f'edge {u}-{v}'))
                 for u, neighbours in (data.get('edge') or {}).items()
                 for v in (neighbours or {})]
    springs, seen = [], set()
    for i, j in pairs:
        if i == j:
            raise ValueError(f'{path}: vertex {list(keys)[i]} is tied to itself')
        if (key := (min(i, j), max(i, j))) not in seen:
            seen.add(key)
            springs.append((i, j))
    return NetData(np.array(positions), np.array(springs, dtype=int).reshape(-1, 2),
                   faces, anchors)


def _edge_attributes(data: dict[str, Any], keys: dict[str, int]
                     ) -> dict[tuple[int, int], dict[str, Any]]:
    """The attribute dicts of the edges of COMPAS ``data`` (the document's
    own, to read or change), by sorted pair of point indices: a graph's
    ``edge[u][v]``, a mesh's ``edgedata`` (keys ``"(u, v)"`` or ``"u-v"``)."""
    if 'face' in data:
        items = []
        for key, attributes in (data.get('edgedata') or {}).items():
            text = str(key).strip('()[] ')
            ends = [end.strip() for end in text.split(',' if ',' in text else '-')]
            items.append((ends, attributes))
    else:
        items = [((u, v), attributes) for u, neighbours in (data.get('edge') or {}).items()
                 for v, attributes in (neighbours or {}).items()]
    found = {}
    for ends, attributes in items:
        if len(ends) == 2 and all(str(end) in keys for end in ends) \
                and isinstance(attributes, dict):
            i, j = (keys[str(end)] for end in ends)
            found[(min(i, j), max(i, j))] = attributes
    return found


def _compas_value(path, where, name, attributes, defaults, fallback):
    """Attribute ``name`` of an item (else the file's default, else
    ``fallback``) checked by ``checks.RULES`` (``q`` or ``loads``), or a
    ValueError naming the file and ``where``."""
    value = attributes.get(name, defaults.get(name, fallback))
    try:
        return check('q' if name == 'q' else 'loads', value)
    except ValueError as error:
        raise ValueError(f'{path}: {where}, attribute {name}: {error}') from None


def _compas_forces(path, data, springs):
    """``q`` (K,) and loads (N, 3) a COMPAS document says (1 and 0 where it
    says nothing), and whether it says anything of each."""
    points, vertex_defaults = _compas_points(path, data)
    keys = {str(k): n for n, k in enumerate(points)}
    edge_defaults = data.get('default_edge_attributes', data.get('dea', {})) or {}
    edges = _edge_attributes(data, keys)
    q = np.array([_compas_value(path, f'edge {i}-{j}', 'q', edges.get((min(i, j), max(i, j)), {}),
                                edge_defaults, 1.0) for i, j in springs])
    loads = np.array([[_compas_value(path, f'vertex {key}', name, attributes, vertex_defaults, 0.0)
                       for name in LOAD_ATTRIBUTES] for key, attributes in points.items()])
    said_q = 'q' in edge_defaults or any('q' in a for a in edges.values())
    said_loads = any(name in vertex_defaults or any(name in a for a in points.values())
                     for name in LOAD_ATTRIBUTES)
    return q.reshape(len(springs)), loads.reshape(-1, 3), said_q, said_loads


def read_compas_forces(path: PathLike, springs: np.ndarray) -> dict[str, np.ndarray]:
    """The force densities ``q`` of ``springs`` (as :func:`read_compas` gives
    them) and the loads of a COMPAS JSON file, as calculator parameters:
    only those the file says anything of (see the module docstring)."""
    _, data = _compas_data(path)
    q, loads, said_q, said_loads = _compas_forces(path, data, springs)
    return {**({'q': q} if said_q else {}), **({'loads': loads} if said_loads else {})}


def write_net(path: PathLike, atoms: Atoms, like: PathLike | None = None) -> list[Path]:
    """Write the net ``atoms`` (with a MaudCalculator) to ``path``; return
    the files written.

    The format is ``path``'s (see the module docstring). ``like``, a file of
    the same format with as many points (the one the net was read from),
    is kept as it is but for the coordinates that moved, each written as
    the shortest text that reads back as its float (an unmoved coordinate
    keeps its text); line endings, comments, faces, curves, groups, COMPAS
    attributes and layout stay (a COMPAS file whose ``q`` or loads changed is
    written anew, without its layout). Without it: OBJ gets the springs as
    ``l`` lines, JSON a COMPAS 2.x graph (fixed points ``is_anchor``, loads
    ``px``, ``py``, ``pz``, force densities ``q``). A trajectory stores the
    springs, ``a``, ``Q``, ``dim``, ``q`` and ``loads`` with the frame; OBJ
    and the other formats hold no ``q`` or loads. ``.xyz``
    (``.extxyz``) is extended XYZ with every digit of the coordinates
    (ASE's writer keeps 8 decimals) and the fixed points as ``move_mask``;
    any other format is written by ASE. Both get the edge list at
    :func:`edges_path`.
    """
    path = Path(path)
    kind = net_format(path)
    if like is not None and net_format(like) != kind:
        raise ValueError(f'cannot write {path.name} like {Path(like).name}: '
                         'they are of different formats')
    # everything is read (``like`` may be ``path``) before anything is
    # replaced, and each file is replaced whole (ase_maud.atomic)
    if kind == 'obj':
        replace_text(path, _obj_text(atoms, like), newline='')
    elif kind == 'json':
        replace_text(path, _compas_text(atoms, like), newline='')
    elif kind == 'traj':
        replace_with(path, lambda temporary: ase.io.write(temporary, atoms, format='traj'))
    else:
        if path.suffix.lower() in ('.xyz', '.extxyz'):
            replace_text(path, _extxyz_text(atoms))
        else:
            replace_with(path, lambda temporary: ase.io.write(temporary, atoms))
        edges = edges_path(path)
        springs = '\n'.join(f'{i} {j}' for i, j in atoms.calc.springs)
        replace_text(edges, f'# springs of {path.name}: two 0-based point indices a line\n'
                     + springs + ('\n' if springs else ''))
        return [path, edges]
    return [path]


def _coordinates(x):
    return ' '.join(repr(float(c)) for c in x)


def _extxyz_text(atoms):
    """Extended XYZ of the symbols, positions (shortest exact repr) and,
    if any point is fixed, ``move_mask`` (F for fixed), as ASE reads it."""
    fixed = fixed_atoms(atoms)
    mask = ':move_mask:L:1' if fixed.any() else ''
    rows = [f'{symbol} {_coordinates(x)}{" F" if held else " T" if mask else ""}\n'
            for symbol, x, held in zip(atoms.get_chemical_symbols(), atoms.positions,
                                       fixed, strict=True)]
    return (f'{len(atoms)}\nProperties=species:S:1:pos:R:3{mask} pbc="F F F"\n'
            + ''.join(rows))


def _original_text(path):
    """The text of ``path`` as it is: line endings kept, a UTF-8 byte-order
    mark apart: (mark or '', the rest)."""
    with open(path, encoding='utf-8', newline='') as f:
        text = f.read()
    mark = text[:1] if text.startswith('\ufeff') else ''
    return mark, text[len(mark):]


def _number_text(old: str, value: float) -> str:
    """``old`` (a number's text in a file) if it reads as ``value``, else
    the shortest text that reads back as ``value`` exactly (``repr``)."""
    return old if float(old) == value else repr(float(value))


#: An OBJ ``v`` statement's keyword and x, y, z with the space around them.
_VERTEX = re.compile(r'(\s*v\s+)([^\s#]+)(\s+)([^\s#]+)(\s+)([^\s#]+)')


def _obj_text(atoms, like):
    """The OBJ text of ``atoms``: ``like`` as it is but for the coordinates
    that moved, or points and ``l`` springs."""
    if like is None:
        lines = [f'v {_coordinates(x)}' for x in atoms.positions]
        lines += [f'l {i + 1} {j + 1}' for i, j in atoms.calc.springs]
        return '\n'.join(['# written by ase_maud', *lines]) + '\n'
    net, point_of, rows = _obj_file(like)
    if len(net.positions) != len(atoms):
        raise ValueError(f'{like} has {len(net.positions)} points ({len(point_of)} '
                         f'vertices, coincident ones merged), the net {len(atoms)}')
    mark, text = _original_text(like)
    lines = list(StringIO(text, newline=''))
    for row, point in zip(rows, point_of, strict=True):
        line = lines[row - 1]
        match = _VERTEX.match(line)
        new = [_number_text(match[k], x) for k, x in zip((2, 4, 6), atoms.positions[point],
                                                          strict=True)]
        lines[row - 1] = (match[1] + new[0] + match[3] + new[1] + match[5] + new[2]
                          + line[match.end():])
    return mark + ''.join(lines)


#: A JSON string (skipped) or number (group 1).
_JSON_TOKEN = re.compile(r'"(?:[^"\\]|\\.)*"|(-?(?:0|[1-9]\d*)(?:\.\d+)?(?:[eE][+-]?\d+)?)')


class _PlacedInt(int):
    """An integer of a JSON text; ``place``: its place among the text's numbers."""


class _PlacedFloat(float):
    """A float of a JSON text; ``place``: its place among the text's numbers."""


def _placed(places):
    """A JSON number hook that gives each number its place from ``places``."""
    def number(text):
        kind = _PlacedInt if text.lstrip('-').isdigit() else _PlacedFloat
        value = kind(text)
        value.place = next(places)
        return value
    return number


def _compas_text(atoms, like):
    """The COMPAS JSON text of ``atoms``: ``like`` as it is but for the
    x, y, z that moved, or a COMPAS 2.x graph. A file whose ``q`` or loads
    the net changes, or with a vertex that takes a coordinate from the
    defaults and moves in it, is written anew, without its layout."""
    potential = atoms.calc.potential
    q = np.broadcast_to(potential.stiffnesses, len(potential.springs))
    loads = np.zeros((len(atoms), 3)) if potential.loads is None else potential.loads
    if like is None:
        return json.dumps(_compas_graph(atoms, q, loads))
    places = itertools.count()
    document, data = _compas_data(like, number=_placed(places))
    points, defaults = _compas_points(like, data)
    if len(points) != len(atoms):
        raise ValueError(f'{like} has {len(points)} vertices, the net {len(atoms)} points')
    mark, text = _original_text(like)
    spans = [m.span(1) for m in _JSON_TOKEN.finditer(text) if m[1]]
    assert len(spans) == next(places), 'JSON numbers miscounted'
    edits, layout = {}, True
    for attributes, x in zip(points.values(), atoms.positions, strict=True):
        for axis, value in zip('xyz', map(float, x), strict=True):
            old = attributes.get(axis)
            if isinstance(old, (_PlacedInt, _PlacedFloat)):
                start, stop = spans[old.place]
                edits[start] = (stop, _number_text(text[start:stop], value))
            elif value != defaults.get(axis):
                layout = False
            attributes[axis] = value
    if _update_forces(like, data, atoms.calc.springs, q, loads) or not layout:
        return json.dumps(document)
    pieces, done = [mark], 0
    for start in sorted(edits):
        stop, new = edits[start]
        pieces += [text[done:start], new]
        done = stop
    return ''.join(pieces + [text[done:]])


def _update_forces(path, data, springs, q, loads) -> bool:
    """Set ``q`` and ``px``, ``py``, ``pz`` in COMPAS ``data`` (read from
    ``path``) where the net's differ from what it says; a mesh edge without
    attributes gets an ``edgedata`` entry, a spring that is no edge of the
    file (from an edge list) no ``q``. Whether anything was set."""
    points, _ = _compas_points(path, data)
    keys = list(points)
    file_q, file_loads = _compas_forces(path, data, springs)[:2]
    changed = False
    for n in np.flatnonzero((file_loads != loads).any(axis=1)):
        points[keys[n]].update(zip(LOAD_ATTRIBUTES, map(float, loads[n]), strict=True))
        changed = True
    edges = _edge_attributes(data, {str(k): n for n, k in enumerate(keys)})
    file_edges = {(min(i, j), max(i, j)) for i, j in read_compas(path).springs.tolist()}
    for s in np.flatnonzero(file_q != q):
        i, j = sorted(springs[s].tolist())
        if (i, j) not in file_edges:
            continue
        if (i, j) not in edges:   # a mesh edge without edgedata
            edges[(i, j)] = data.setdefault('edgedata', {})[f'({keys[i]}, {keys[j]})'] = {}
        edges[(i, j)]['q'] = float(q[s])
        changed = True
    return changed


def _compas_graph(atoms, q, loads):
    """A COMPAS 2.x graph document of ``atoms``: fixed points ``is_anchor``,
    non-zero ``loads`` as ``px``, ``py``, ``pz``, force densities ``q`` on
    every edge where the calculator has them."""
    fixed = set(np.flatnonzero(fixed_atoms(atoms)).tolist())
    node = {str(n): {'x': float(x), 'y': float(y), 'z': float(z),
                     **({'is_anchor': True} if n in fixed else {}),
                     **(dict(zip(LOAD_ATTRIBUTES, map(float, loads[n]), strict=True))
                        if loads[n].any() else {})}
            for n, (x, y, z) in enumerate(atoms.positions)}
    edge = {str(n): {} for n in range(len(atoms))}
    for (i, j), qs in zip(atoms.calc.springs, q, strict=True):
        edge[str(i)][str(j)] = {} if atoms.calc.potential.q is None else {'q': float(qs)}
    data = {'attributes': {}, 'default_node_attributes': {'x': 0.0, 'y': 0.0, 'z': 0.0},
            'default_edge_attributes': {}, 'node': node, 'edge': edge,
            'max_node': len(atoms) - 1}
    return {'dtype': 'compas.datastructures/Graph', 'data': data,
            'guid': str(uuid.uuid4())}
