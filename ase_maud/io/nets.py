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
  compas_fd, an edge attribute ``q`` is the spring's force density ``Q q``
  (the calculator's ``q`` times the ``Q`` the file stores in its
  ``attributes.ase_maud``, with ``a``, where this package wrote it: a net
  written is read back as it was, its ``a`` and ``Q`` the defaults) and
  vertex attributes ``px``, ``py``, ``pz`` its load (the calculator's
  ``loads``), each from the item's own attributes, else the file's
  defaults, else 1 and 0. Written back as the original structure with
  ``x``, ``y``, ``z`` replaced, and ``q``, ``px``, ``py``, ``pz`` set
  where the net's differ from the file's.
- ``.ply``, ``.stl``, ``.off``, ``.vtk``, ``.vtu``, meshes read through
  meshio (:mod:`ase_maud.io.mesh`): the springs are the faces' edges
  and the line cells; coincident points merged. Written back in the same
  format with the faces read (``atoms.info['faces']``) and the other
  springs as lines (STL and OFF: triangles only).
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

Reader choice: our own OBJ parser (numpy on a plain file, several times
faster than statement by statement and than meshio's reader; statement by
statement, with line numbers in its errors, on anything else). meshio's OBJ
reader skips ``l`` lines and reports no line numbers; trimesh triangulates quads, adding
a diagonal spring to every quad. Neither keeps the rest of the file for
writing back. COMPAS's JSON is plain JSON: the standard library reads it.

Malformed input is a ValueError naming the file, the line (where the format
has lines) and what was expected.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import ase.io
import ase.io.formats
import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian
from ase.io.trajectory import Trajectory

from ase_maud.calculator.identify import CALC_NAME, stored_parameters
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import as_whole, check, check_writable, did_you_mean
from ase_maud.files.trajectory import first_frame
from ase_maud.io.compas import read_compas, read_compas_forces
from ase_maud.io.mesh import MESH_FORMATS, read_mesh
from ase_maud.io.net_data import MERGE_TOLERANCE, NetData, PathLike, merge_coincident
from ase_maud.io.obj import read_obj
from ase_maud.io.tables import read_loads_csv, read_q_csv
from ase_maud.io.text import XYZ_SUFFIXES, check_xyz_counts, read_edges, read_indices
from ase_maud.physics.dofs import keep_on_plane
from ase_maud.physics.topology import (
    A_PER_MEAN_SPRING,
    boundary_vertices,
    default_a,
    free_point_loads,
    leaf_vertices,
    mean_spring_length,
    outer_rim,
)

if TYPE_CHECKING:
    pass

__all__ = ['A_PER_MEAN_SPRING', 'CALC_NAME', 'FIX_RULES', 'MERGE_TOLERANCE', 'NetData',
           'READ_FORMATS',
           'check_net_path', 'default_a', 'edges_path', 'mean_spring_length',
           'merge_coincident', 'net_format', 'read_compas', 'read_compas_forces',
           'read_edges', 'read_frames', 'read_indices', 'read_net', 'read_obj',
           'relaxed_fmax', 'set_tables', 'stored_parameters']


#: The rules ``fixed=`` takes by name (:func:`read_net`).
FIX_RULES = ('boundary', 'outer', 'leaves')


def net_format(path: PathLike) -> str:
    """'obj', 'json', 'traj', 'mesh' (:data:`MESH_FORMATS`, through meshio) or
    'ase' (any other file ASE reads), by suffix."""
    suffix = Path(path).suffix.lower()
    if suffix in MESH_FORMATS:
        return 'mesh'
    return {'.obj': 'obj', '.json': 'json', '.traj': 'traj'}.get(suffix, 'ase')


#: The formats a net is read from, in words (a refused file names them).
READ_FORMATS = ('OBJ (.obj), COMPAS JSON (.json), an ASE trajectory (.traj), meshes '
                f'through meshio ({", ".join(MESH_FORMATS)}), or extended XYZ (.xyz) and '
                'any other file ASE reads, with an edge list')


def check_net_path(name: str, path: PathLike) -> Path:
    """``path`` checked as a file :func:`write_net` can write, before any
    work: a writable file (:func:`~ase_maud.checks.check_writable`) whose
    suffix names a format (one of :func:`net_format`'s, or one ASE writes);
    else a ValueError naming ``name``, the file and what is accepted."""
    path = check_writable(name, path)
    if net_format(path) == 'ase' and path.suffix.lower() not in XYZ_SUFFIXES:
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
    fixed : 'boundary', 'outer', 'leaves', file name or indices, optional
        Points held fixed (:class:`FixAtoms`), replacing the constraints
        read from the file: ``'boundary'``, the boundary of a mesh's faces
        (:func:`~ase_maud.physics.topology.boundary_vertices`; OBJ, COMPAS and
        mesh files); ``'outer'``, its outer rim alone, not the rims of its
        holes (:func:`~ase_maud.physics.topology.outer_rim`); ``'leaves'``, the points on one spring
        (:func:`~ase_maud.physics.topology.leaf_vertices`); a file of 0-based
        indices, one or more per line (a ``Path`` is always a file); or the
        indices.
    a, Q : float, optional
        Length and spring constant of the potential. Default ``a``: what a
        trajectory stores (1 if it stores its calculator without ``a``),
        else :func:`default_a` of the net (0, the force-density
        equilibrium, where its supports make it unique); ``Q``: what a trajectory
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

    Returns
    -------
    Atoms
        The points (in the file's length unit), their supports as
        ``FixAtoms``, and a :class:`~ase_maud.MaudCalculator` with the
        springs, ``a``, ``Q``, ``dim``, force densities ``q`` and loads
        (force units ``Q a``).

    Raises
    ------
    ValueError
        A file that cannot be read or is malformed (the file, and the line
        where the format has lines), a format no reader takes, a net with
        no springs, a frame beyond the file's (``no frame -999: the file
        holds 4 frames ...``), a ``fixed`` rule that finds no point or a
        fixed point out of range or given twice, an edge listed twice with
        two ``q``, or ``a``, ``Q``, ``dim``, ``load`` outside their rules.
    OSError
        The file cannot be opened.
    """
    return _read(path, edges, fixed, a, Q, dim, index, load)[0]


def read_frames(path: PathLike, edges: PathLike | None = None,
                fixed: PathLike | Sequence[int] | None = None,
                a: float | None = None, Q: float | None = None,
                dim: int | None = None,
                load: Sequence[float] | None = None) -> list[Atoms]:
    """Every frame of a file (one for OBJ and JSON), as :func:`read_net`.

    Parameters
    ----------
    path, edges, fixed, a, Q, dim, load
        As for :func:`read_net`.

    Returns
    -------
    list of Atoms
        One net per frame, in the file's order, each with its own
        :class:`~ase_maud.MaudCalculator`.

    Raises
    ------
    ValueError
        As :func:`read_net`.
    OSError
        The file cannot be opened.
    """
    return _read(path, edges, fixed, a, Q, dim, slice(None), load)


def _read(path, edges, fixed, a, Q, dim, index, load=None):
    """Frames of ``path`` with their calculators, as :func:`read_net` says."""
    if Path(path).is_dir():
        raise ValueError(f'{path} is a directory, not a net file')
    kind = net_format(path)
    faces = []
    if not isinstance(index, slice):
        index = _whole_index(index)
    if kind in ('obj', 'json', 'mesh'):
        if not isinstance(index, slice):
            _check_frame(path, index, 1)
        positions, springs, faces, anchors = {'obj': read_obj, 'json': read_compas,
                                              'mesh': read_mesh}[kind](path)
        faces = _faces_once(path, faces)
        frames = [Atoms(positions=positions, pbc=False)]
        if len(faces):   # written back with the net (write_net)
            frames[0].info['faces'] = faces
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
        indices = _fixed_points(path, fixed, frames[0].positions, stored['springs'], faces)
        for atoms in frames:
            atoms.set_constraint(FixAtoms(indices=indices))
    if 'a' not in parameters:
        parameters['a'] = default_a(frames[0], stored['springs'])
    for atoms in frames:
        atoms.pbc = False
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


def _faces_once(path, faces):
    """``faces`` with each face listed twice or more (the same corners, in any
    order or direction) kept once, a warning naming the first repeat: a face
    twice would make its edges look inner to --fix boundary."""
    seen, once, repeats = {}, [], []
    for number, face in enumerate(faces):
        key = tuple(sorted(face))
        if key in seen:
            repeats.append((number, seen[key]))
        else:
            seen[key] = number
            once.append(face)
    if repeats:
        number, first = repeats[0]
        warnings.warn(f'{path}: {len(repeats)} face(s) listed again, read once (face '
                      f'{number}, 0-based, repeats face {first})', stacklevel=4)
    return once


def _fixed_points(path, fixed, positions, springs, faces):
    """The indices ``fixed=`` names (:func:`read_net`), checked."""
    natoms = len(positions)
    if isinstance(fixed, str) and fixed in FIX_RULES:
        if fixed in ('boundary', 'outer') and not len(faces):
            raise ValueError(f"{path}: fixed={fixed!r} needs a mesh's faces and the "
                             "file has none (OBJ 'f' lines, a COMPAS mesh or a mesh "
                             "file); 'leaves' fixes the ends of a network's lines")
        indices = {'boundary': lambda: boundary_vertices(faces),
                   'outer': lambda: outer_rim(faces, positions),
                   'leaves': lambda: leaf_vertices(natoms, springs)}[fixed]()
        if not len(indices):
            raise ValueError(f"{path}: fixed={fixed!r} finds no point (" + (
                'no point is on exactly one spring; \'boundary\' fixes a mesh\'s'
                if fixed == 'leaves' else 'every edge is in two faces: a closed mesh')
                + '); name the fixed points')
        return indices.tolist()
    if isinstance(fixed, str) and not Path(fixed).exists():
        raise ValueError(f'fixed={fixed!r} is neither a rule ({", ".join(FIX_RULES)}) '
                         'nor a file' + did_you_mean(fixed, FIX_RULES))
    if isinstance(fixed, (str, os.PathLike)):
        return read_indices(fixed, natoms)
    return _fixed_indices(fixed, natoms)


def set_tables(atoms: Atoms, loads: PathLike | None = None,
               q: PathLike | None = None, dim: int | None = None) -> None:
    """Set the loads and force densities of the net ``atoms`` (with a
    MaudCalculator) from CSV tables (:mod:`ase_maud.io.tables`): the
    loads replace the calculator's, the force densities replace those of
    the edges listed. ``q`` may also be one number, every spring's (a
    negative one: every member in compression, an arch or a gridshell). None
    leaves either as it is. A flat net (``dim=2``) whose loads leave its
    plane becomes 3D, as :func:`read_net` makes it when it reads them,
    unless ``dim`` (the user's) is 2."""
    if loads is not None:
        table = read_loads_csv(loads, len(atoms))
        if atoms.calc.dim == 2 and dim is None and np.any(table[:, 2]):
            atoms.set_constraint([c for c in atoms.constraints if not (
                isinstance(c, FixCartesian) and list(c.mask) == [False, False, True])])
            atoms.calc.set(dim=3, loads=table)
        else:
            atoms.calc.set(loads=table)
    if q is not None and (every := _one_number(q)) is not None:
        atoms.calc.set(q=np.full(len(atoms.calc.potential.springs), check('q', every)))
    elif q is not None:
        potential = atoms.calc.potential
        current = np.broadcast_to(potential.stiffnesses, len(potential.springs))
        atoms.calc.set(q=read_q_csv(q, potential.springs, current, len(atoms)))


def _one_number(text) -> float | None:
    """``text`` as a float if it is one number (not a path), else None."""
    if not isinstance(text, str) or Path(text).exists():
        return None
    try:
        return float(text)
    except ValueError:
        return None


def _whole_index(index):
    """A frame index as an int, or a ValueError naming it."""
    whole = as_whole(index)
    if whole is None or isinstance(index, float):
        raise ValueError(f'index must be a whole number (a frame, 0-based; -1 the last), '
                         f'got {index!r}')
    return whole


def _check_frame(path, index, count):
    """ValueError naming ``path`` and its ``count`` frames unless frame
    ``index`` is one of them (``-count <= index < count``)."""
    if not -count <= index < count:
        held = ('one frame (index 0 or -1)' if count == 1 else
                f'{count} frames (0 to {count - 1}, or -1 to -{count})')
        raise ValueError(f'{path}: no frame {index}: the file holds {held}')


def _read_ase(path, index):
    """Frames of an ASE-readable file (``index``: an int, checked against
    the file's frames, or a slice), and the MaudCalculator parameters its
    (first) frame stores, if any."""
    if Path(path).suffix.lower() in XYZ_SUFFIXES:
        check_xyz_counts(path)   # ASE allocates what a file declares
    try:
        if isinstance(index, slice):
            frames = ase.io.read(path, index)
        elif net_format(path) == 'traj':   # counted without reading the frames
            with Trajectory(path) as trajectory:
                count = len(trajectory)
                frames = [trajectory[index]] if -count <= index < count else []
        else:
            frames = ase.io.read(path, ':')
            count = len(frames)
            frames = [frames[index]] if -count <= index < count else []
    except FileNotFoundError:
        raise
    except Exception as error:   # ASE's readers raise many kinds
        raise ValueError(f'{path}: ASE cannot read it ({type(error).__name__}: '
                         f'{error}); a net is read from {READ_FORMATS}') from error
    if not isinstance(index, slice):
        _check_frame(path, index, count)
    frames = frames if isinstance(frames, list) else [frames]
    if not frames:
        raise ValueError(f'{path}: no frame at index {index}')
    stored = stored_parameters(frames[0])
    if not stored and net_format(path) == 'traj' and getattr(
            frames[0].calc, 'name', '') == CALC_NAME:   # a run's: with its first frame only
        first = first_frame(path)
        stored = {} if first is None else stored_parameters(first)
    if stored:   # a calculator stored without a has the default a
        stored.setdefault('a', MaudCalculator.default_parameters['a'])
    for atoms in frames:
        atoms.calc = None
    return frames, stored


def _fixed_indices(indices, natoms):
    """``indices`` as a list of ints in ``range(natoms)``, or ValueError."""
    checked = [as_whole(i) for i in indices]
    for given, i in zip(indices, checked, strict=True):
        if i is None:
            raise ValueError(f'fixed point {given!r} is not a whole number (0-based index)')
        if not 0 <= i < natoms:
            raise ValueError(f'fixed point {i} out of range ({natoms} points, 0-based)')
    if len(set(checked)) < len(checked):
        twice = next(i for n, i in enumerate(checked) if i in checked[:n])
        raise ValueError(f'fixed point {twice} is given twice')
    return checked
