"""Nets written to files: :func:`write_net`, the format chosen by the
file's suffix (OBJ, PLY, STL, OFF, VTK, VTU, COMPAS JSON, points with an edge
list, ASE's formats), through :mod:`ase_maud.io`'s writer of each, replacing
the file atomically."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import ase.io
import ase.io.formats
from ase import Atoms

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.files.atomic_replace import replace_text, replace_with
from ase_maud.io.compas import compas_text
from ase_maud.io.mesh import write_mesh
from ase_maud.io.net_data import PathLike
from ase_maud.io.nets import edges_path, net_format
from ase_maud.io.obj import obj_text
from ase_maud.io.text import XYZ_SUFFIXES, coordinates
from ase_maud.physics.topology import fixed_atoms

if TYPE_CHECKING:
    from ase_maud.form.member_forces import FormResult


def write_net(path: PathLike, atoms: Atoms, like: PathLike | None = None,
              result: FormResult | None = None) -> list[Path]:
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
    and the other formats hold no ``q`` or loads. The faces a net was read
    with (``atoms.info['faces']``) are written to OBJ (``f`` lines, the
    other springs as ``l``) and to the meshes of :data:`MESH_FORMATS`
    (:func:`~ase_maud.io.mesh.write_mesh`), from whatever file they came. ``.xyz``
    (``.extxyz``) is extended XYZ with every digit of the coordinates
    (ASE's writer keeps 8 decimals) and the fixed points as ``move_mask``;
    any other format is written by ASE. Both get the edge list at
    :func:`edges_path`. COMPAS JSON keeps the supports as ``is_anchor``
    and, given a ``result`` (:func:`ase_maud.form.member_forces.form_result` of
    ``atoms``), holds the member forces and reactions
    (:func:`~ase_maud.io.compas.compas_text`); the other formats ignore
    ``result``.

    Parameters
    ----------
    path : file name
        Where to write; its suffix chooses the format (``.obj``, ``.json``,
        ``.traj``, ``.xyz``, or any ASE writes). Replaced whole, atomically,
        keeping the old file's permissions.
    atoms : Atoms
        The net, with a :class:`~ase_maud.MaudCalculator`.
    like : file name or None, default None
        The file the net was read from, kept but for the moved coordinates.
    result : FormResult or None, default None
        Member forces and reactions to store (COMPAS JSON only).

    Returns
    -------
    list of Path
        The files written (the net, and an edge list beside it where the
        format holds no springs).

    Raises
    ------
    ValueError
        Atoms without a MaudCalculator, a suffix no writer takes, a
        ``like`` of another format or number of points, or a path that
        cannot be written (a missing or read-only directory).
    OSError
        The disk refused the write (the old file is left whole).
    """
    path = Path(path)
    kind = net_format(path)
    if not isinstance(atoms.calc, MaudCalculator):
        raise ValueError(f'cannot write {path.name}: the net needs its MaudCalculator '
                         '(the springs, a, Q), and the atoms have ' + (
                             'no calculator' if atoms.calc is None else
                             f'a {type(atoms.calc).__name__}'))
    if like is not None and net_format(like) != kind:
        raise ValueError(f'cannot write {path.name} like {Path(like).name}: '
                         'they are of different formats')
    # everything is read (``like`` may be ``path``) before anything is
    # replaced, and each file is replaced whole (ase_maud.files.atomic_replace)
    if kind == 'obj':
        replace_text(path, obj_text(atoms, like), newline='')
    elif kind == 'mesh':
        write_mesh(path, atoms.positions, atoms.info.get('faces'), atoms.calc.springs)
    elif kind == 'json':
        replace_text(path, compas_text(atoms, like, result), newline='')
    elif kind == 'traj':
        replace_with(path, lambda temporary: ase.io.write(temporary, atoms, format='traj'))
    else:
        if path.suffix.lower() in XYZ_SUFFIXES:
            replace_text(path, _extxyz_text(atoms))
        else:
            replace_with(path, lambda temporary: ase.io.write(temporary, atoms))
        edges = edges_path(path)
        springs = '\n'.join(f'{i} {j}' for i, j in atoms.calc.springs)
        replace_text(edges, f'# springs of {path.name}: two 0-based point indices a line\n'
                     + springs + ('\n' if springs else ''))
        return [path, edges]
    return [path]


def _extxyz_text(atoms):
    """Extended XYZ of the symbols, positions (shortest exact repr) and,
    if any point is fixed, ``move_mask`` (F for fixed), as ASE reads it."""
    fixed = fixed_atoms(atoms)
    mask = ':move_mask:L:1' if fixed.any() else ''
    rows = [f'{symbol} {coordinates(x)}{" F" if held else " T" if mask else ""}\n'
            for symbol, x, held in zip(atoms.get_chemical_symbols(), atoms.positions,
                                       fixed, strict=True)]
    return (f'{len(atoms)}\nProperties=species:S:1:pos:R:3{mask} pbc="F F F"\n'
            + ''.join(rows))
