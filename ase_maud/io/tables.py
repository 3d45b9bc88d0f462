"""Per-point loads and per-edge force densities from CSV tables (a
spreadsheet's export), for ``ase-maud relax --loads`` and ``--q``.

- loads: a header ``i,px,py,pz`` (compas_fd's names), then one row per
  loaded point: its 0-based index and its load in force units. Points not
  listed carry no load.
- force densities: a header ``i,j,q``, then one row per edge: its two
  0-based point indices (either order) and its force density multiplier of
  ``Q`` (the calculator's ``q``). Edges not listed keep the ``q`` they had.

Every value is checked by its rule (:mod:`ase_maud.checks`); a ValueError
names the file, the line and what is wrong.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator

import numpy as np

from ase_maud.checks import as_whole, check
from ase_maud.io.net_data import PathLike

LOAD_COLUMNS = ('i', 'px', 'py', 'pz')
Q_COLUMNS = ('i', 'j', 'q')


def _rows(path: PathLike, columns: tuple[str, ...]) -> Iterator[tuple[int, list[str]]]:
    """(line number, values in the order of ``columns``) of every row of the
    CSV file ``path`` after its header, which must name ``columns``."""
    try:
        with open(path, encoding='utf-8-sig', newline='') as f:
            table = csv.reader(f)
            header = [name.strip() for name in next(table, [])]
            if sorted(header) != sorted(columns):
                raise ValueError(f'{path} line 1: expected the header {",".join(columns)}, '
                                 f'got {",".join(header)!r}')
            where = [header.index(name) for name in columns]
            for row in table:
                if not any(cell.strip() for cell in row):
                    continue
                if len(row) != len(columns):
                    raise ValueError(f'{path} line {table.line_num}: expected '
                                     f'{len(columns)} values ({",".join(columns)}), '
                                     f'got {len(row)}')
                yield table.line_num, [row[k].strip() for k in where]
    except UnicodeDecodeError:
        raise ValueError(f'{path}: not UTF-8 text') from None


def _index(path, line, text, natoms):
    """A 0-based point index, or a ValueError naming the line."""
    try:
        value = as_whole(float(text))
    except ValueError:
        value = None
    if value is None or not 0 <= value < natoms:
        raise ValueError(f'{path} line {line}: point index {text!r} is not a whole number '
                         f'in 0..{natoms - 1}')
    return value


def _number(path, line, name, text):
    """``text`` checked by the rule of ``name`` ('loads' or 'q')."""
    try:
        number = float(text)
    except ValueError:
        raise ValueError(f'{path} line {line}: {name} must be a number, got {text!r}') from None
    try:
        return check(name, number)
    except ValueError as error:
        raise ValueError(f'{path} line {line}: {error}') from None


def read_loads_csv(path: PathLike, natoms: int) -> np.ndarray:
    """The loads (natoms, 3) of a CSV table (see the module docstring)."""
    loads = np.zeros((natoms, 3))
    seen: dict[int, int] = {}
    for line, (i, *values) in _rows(path, LOAD_COLUMNS):
        n = _index(path, line, i, natoms)
        if n in seen:
            raise ValueError(f'{path} line {line}: point {n} is loaded on line {seen[n]} '
                             'already; list each point once')
        seen[n] = line
        loads[n] = [_number(path, line, 'loads', v) for v in values]
    return loads


def read_q_csv(path: PathLike, springs: np.ndarray, q: np.ndarray,
               natoms: int) -> np.ndarray:
    """``q`` (K,) of ``springs`` (K, 2) of a net of ``natoms`` points with
    the force densities of a CSV table set (see the module docstring); a row
    whose pair is no spring is a ValueError."""
    where = {(min(i, j), max(i, j)): s for s, (i, j) in enumerate(springs.tolist())}
    q = np.array(q, dtype=float)
    seen: dict[int, int] = {}
    for line, (i, j, value) in _rows(path, Q_COLUMNS):
        a, b = (_index(path, line, text, natoms) for text in (i, j))
        s = where.get((min(a, b), max(a, b)))
        if s is None:
            raise ValueError(f'{path} line {line}: points {a} and {b} are tied by no spring')
        if s in seen:
            raise ValueError(f'{path} line {line}: the spring {a}-{b} is on line {seen[s]} '
                             'already; list each edge once')
        seen[s] = line
        q[s] = _number(path, line, 'q', value)
    return q
