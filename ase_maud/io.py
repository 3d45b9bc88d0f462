"""Nets from files and back: points, springs, and the Maud parameters.

:func:`read_net` returns an :class:`ase.Atoms` (``pbc=False``) with a
:class:`~ase_maud.MaudCalculator` attached; its ``calc.springs`` are the
file's edges. :func:`write_net` writes a (relaxed) net back, in the format
its file name says, keeping the rest of an original file (``like=``).

Formats, chosen by the file name's suffix:

- ``.obj``, Wavefront OBJ: each ``v`` line is a point; the springs are the
  edges of the faces (``f``), each undirected edge once, plus the segments of
  the polylines (``l``). Indices may be ``v``, ``v/vt``, ``v//vn``,
  ``v/vt/vn``, 1-based or negative (relative). Other statements (``vn``,
  ``vt``, ``g``, ``o``, ``usemtl``, ...) are kept on writing and ignored on
  reading. Written back with every ``v`` line's coordinates replaced.
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

Reader choice: our own OBJ parser. meshio's OBJ reader skips
``l`` lines and reports no line numbers; trimesh triangulates quads, adding
a diagonal spring to every quad. Neither keeps the rest of the file for
writing back. COMPAS's JSON is plain JSON: the standard library reads it.

Malformed input is a ValueError naming the file, the line (where the format
has lines) and what was expected.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import ase.io
import ase.io.formats
import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms

from .atomic import replace_text, replace_with
from .calculator import MaudCalculator
from .checks import as_whole, check, check_each, check_writable
from .topology import fixed_atoms

PathLike = str | os.PathLike
#: The name under which ASE's trajectory stores a MaudCalculator.
CALC_NAME = 'maudcalculator'
#: Vertex (node) attributes of COMPAS data that fix a point when true.
ANCHOR_ATTRIBUTES = ('is_anchor', 'is_fixed')
#: Vertex (node) attributes of COMPAS data that hold a load (compas_fd's).
LOAD_ATTRIBUTES = ('px', 'py', 'pz')


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
    fixed : file name or indices, optional
        Points held fixed (:class:`FixAtoms`), 0-based; a file lists them one
        or more per line. Replaces the constraints read from the file.
    a, Q : float, optional
        Length and spring constant of the potential; default: what a
        trajectory stores, else 1.
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


def free_point_loads(atoms: Atoms, load: Sequence[float]) -> np.ndarray:
    """Loads (N, 3): ``load`` (3 numbers, force units) on every point that
    no constraint holds in all three directions, 0 on the others."""
    load = check_each('loads', load, 'component')
    if load.shape != (3,):
        raise ValueError(f'a load on every free point needs 3 numbers (x y z), '
                         f'got shape {load.shape}')
    return np.where(fixed_atoms(atoms)[:, None], 0.0, load)


def _read(path, edges, fixed, a, Q, dim, index, load=None):
    """Frames of ``path`` with their calculators, as :func:`read_net` says."""
    kind = net_format(path)
    if kind in ('obj', 'json'):
        positions, springs, anchors = (read_obj(path) + ([],) if kind == 'obj'
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
    given = {'a': a, 'Q': Q, 'dim': dim}
    parameters = {**stored, **{k: v for k, v in given.items() if v is not None}}
    if fixed is not None:
        indices = (read_indices(fixed, natoms) if isinstance(fixed, (str, os.PathLike))
                   else _fixed_indices(fixed, natoms))
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
    return frames


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
            for number, line in enumerate(f, 1):
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


def _integers(path, number, tokens, what):
    """``tokens`` as ints, or ValueError naming the line and ``what``."""
    try:
        return [int(t) for t in tokens]
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
        pair = _integers(path, number, tokens, 'two integer indices')
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
        for i in _integers(path, number, tokens, 'integer point indices'):
            _check_index(path, number, i, natoms)
            indices.append(i)
    return indices


def read_obj(path: PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and springs (K, 2) of an OBJ file.

    Springs: the edges of every face (``f``) and the segments of every
    polyline (``l``), each undirected pair once, in order of appearance.
    """
    points, springs, seen = [], [], set()
    refs = []   # (line number, element kind, resolved 0-based indices)
    for number, tokens in _lines(path):
        keyword, rest = tokens[0], tokens[1:]
        if keyword == 'v':
            try:
                xyz = [float(t) for t in rest[:3]]
            except ValueError:
                raise ValueError(f"{path} line {number}: expected 'v x y z' "
                                 f'with numbers, got {" ".join(tokens)!r}') from None
            if len(rest) < 3:
                raise ValueError(f"{path} line {number}: expected 'v x y z', "
                                 f'got {len(rest)} coordinates')
            points.append(_finite(path, f'line {number}', xyz))
        elif keyword in ('f', 'l'):
            least = 3 if keyword == 'f' else 2
            if len(rest) < least:
                raise ValueError(f'{path} line {number}: a {keyword!r} needs '
                                 f'at least {least} vertex indices, got {len(rest)}')
            raw = _integers(path, number, [t.split('/')[0] for t in rest],
                            'integer vertex indices (v, v/vt, v//vn or v/vt/vn)')
            if 0 in raw:
                raise ValueError(f'{path} line {number}: vertex index 0 (OBJ '
                                 'counts from 1)')
            # negative indices count back from the last vertex read so far
            refs.append((number, keyword,
                         [i - 1 if i > 0 else len(points) + i for i in raw]))
    for number, keyword, indices in refs:
        for i in indices:
            if not 0 <= i < len(points):
                one_based = i + 1 if i >= 0 else i - len(points)
                kind = 'face' if keyword == 'f' else 'line'
                raise ValueError(f'{path} line {number}: {kind} index '
                                 f'{one_based} out of range ({len(points)} vertices)')
        ring = indices + indices[:1] if keyword == 'f' else indices
        for i, j in zip(ring[:-1], ring[1:], strict=True):
            if i == j:
                raise ValueError(f'{path} line {number}: vertex {i + 1} '
                                 'repeats next to itself (a spring from a '
                                 'point to itself)')
            if (key := (min(i, j), max(i, j))) not in seen:
                seen.add(key)
                springs.append((i, j))
    if not points:
        raise ValueError(f"{path}: no vertices ('v x y z' lines)")
    return (np.array(points, dtype=float),
            np.array(springs, dtype=int).reshape(-1, 2))


def _compas_data(path: PathLike) -> tuple[Any, dict[str, Any]]:
    """The whole JSON document of a COMPAS file and its data dict."""
    def unique_keys(pairs):
        keys = [key for key, _ in pairs]
        if len(set(keys)) < len(keys):
            twice = next(key for key in keys if keys.count(key) > 1)
            raise ValueError(f'{path}: key {twice!r} appears twice in one object '
                             '(JSON keeps only the last; name each vertex once)')
        return dict(pairs)

    try:
        with open(path, encoding='utf-8-sig') as f:
            document = json.load(f, object_pairs_hook=unique_keys)
    except json.JSONDecodeError as error:
        raise ValueError(f'{path} line {error.lineno}: not valid JSON '
                         f'({error.msg})') from None
    except UnicodeDecodeError:
        raise ValueError(f'{path}: not UTF-8 text') from None
    data = document
    if isinstance(data, dict) and 'dtype' in data:
        data = data.get('data', data.get('value'))
    if not isinstance(data, dict) or not ({'vertex', 'face'} <= data.keys()
                                          or 'node' in data):
        raise ValueError(f'{path}: expected COMPAS mesh data ("vertex" and '
                         '"face") or network data ("node" and "edge"), bare or '
                         'in {"dtype": ..., "data"/"value": ...}')
    return document, data


def _compas_points(path, data):
    """The points' dict (vertex or node) and default attributes of ``data``."""
    if 'face' in data:
        return data['vertex'], data.get('default_vertex_attributes', data.get('dva', {}))
    return data['node'], data.get('default_node_attributes', data.get('dna', {}))


def read_compas(path: PathLike) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Points (N, 3), springs (K, 2) and anchors of a COMPAS mesh or network
    JSON file (see the module docstring)."""
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

    if 'face' in data:
        pairs = []
        for fkey, vertices in data['face'].items():
            ring = [index(v, f'face {fkey}') for v in vertices]
            pairs += zip(ring, ring[1:] + ring[:1], strict=True)
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
    return (np.array(positions), np.array(springs, dtype=int).reshape(-1, 2),
            anchors)


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
    is kept but for the coordinates: OBJ faces, polylines, groups and
    comments, COMPAS attributes. Without it: OBJ gets the springs as ``l``
    lines, JSON a COMPAS 2.x graph (fixed points ``is_anchor``, loads
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
        replace_text(path, _obj_text(atoms, like))
    elif kind == 'json':
        replace_text(path, json.dumps(_compas_document(atoms, like)))
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


def _obj_text(atoms, like):
    """The OBJ text of ``atoms``: ``like`` with its ``v`` lines' coordinates
    replaced, or points and ``l`` springs."""
    if like is None:
        lines = [f'v {_coordinates(x)}' for x in atoms.positions]
        lines += [f'l {i + 1} {j + 1}' for i, j in atoms.calc.springs]
        return '\n'.join(['# written by ase_maud', *lines]) + '\n'
    count = sum(1 for _, tokens in _lines(like) if tokens[0] == 'v')
    if count != len(atoms):
        raise ValueError(f'{like} has {count} vertices, the net {len(atoms)} points')
    text, points = [], iter(atoms.positions)
    with open(like) as f:
        for line in f:
            tokens = line.split('#', 1)[0].split()
            if tokens and tokens[0] == 'v':   # keep w or colours after x y z
                line = ' '.join(['v', _coordinates(next(points)), *tokens[4:]]) + '\n'
            text.append(line)
    return ''.join(text)


def _compas_document(atoms, like):
    """The COMPAS JSON document of ``atoms``: ``like``'s with new x, y, z,
    or a COMPAS 2.x graph."""
    potential = atoms.calc.potential
    q = np.broadcast_to(potential.stiffnesses, len(potential.springs))
    loads = np.zeros((len(atoms), 3)) if potential.loads is None else potential.loads
    if like is None:
        fixed = set(np.flatnonzero(fixed_atoms(atoms)).tolist())
        node = {str(n): {'x': float(x), 'y': float(y), 'z': float(z),
                         **({'is_anchor': True} if n in fixed else {}),
                         **(dict(zip(LOAD_ATTRIBUTES, map(float, loads[n]), strict=True))
                            if loads[n].any() else {})}
                for n, (x, y, z) in enumerate(atoms.positions)}
        edge = {str(n): {} for n in range(len(atoms))}
        for (i, j), qs in zip(atoms.calc.springs, q, strict=True):
            edge[str(i)][str(j)] = {} if potential.q is None else {'q': float(qs)}
        data = {'attributes': {}, 'default_node_attributes': {'x': 0.0, 'y': 0.0, 'z': 0.0},
                'default_edge_attributes': {}, 'node': node, 'edge': edge,
                'max_node': len(atoms) - 1}
        return {'dtype': 'compas.datastructures/Graph', 'data': data,
                'guid': str(uuid.uuid4())}
    document, data = _compas_data(like)
    points, _ = _compas_points(like, data)
    if len(points) != len(atoms):
        raise ValueError(f'{like} has {len(points)} vertices, the net {len(atoms)} points')
    for attributes, x in zip(points.values(), atoms.positions, strict=True):
        attributes.update(zip('xyz', map(float, x), strict=True))
    _update_forces(like, data, atoms.calc.springs, q, loads)
    return document


def _update_forces(path, data, springs, q, loads):
    """Set ``q`` and ``px``, ``py``, ``pz`` in COMPAS ``data`` (read from
    ``path``) where the net's differ from what it says; a mesh edge without
    attributes gets an ``edgedata`` entry, a spring that is no edge of the
    file (from an edge list) no ``q``."""
    points, _ = _compas_points(path, data)
    keys = list(points)
    file_q, file_loads = _compas_forces(path, data, springs)[:2]
    for n in np.flatnonzero((file_loads != loads).any(axis=1)):
        points[keys[n]].update(zip(LOAD_ATTRIBUTES, map(float, loads[n]), strict=True))
    edges = _edge_attributes(data, {str(k): n for n, k in enumerate(keys)})
    file_edges = {(min(i, j), max(i, j)) for i, j in read_compas(path)[1].tolist()}
    for s in np.flatnonzero(file_q != q):
        i, j = sorted(springs[s].tolist())
        if (i, j) not in file_edges:
            continue
        if (i, j) not in edges:   # a mesh edge without edgedata
            edges[(i, j)] = data.setdefault('edgedata', {})[f'({keys[i]}, {keys[j]})'] = {}
        edges[(i, j)]['q'] = float(q[s])
