"""Text files of numbers, line by line: the reader of OBJ statements, edge
lists and index lists (:mod:`ase_maud.io` says what each holds), with the
errors that name the file and the line; and numbers written back as text."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np

from ase_maud.io.net_data import PathLike

#: The longest line a text file (OBJ, edge list, indices) may have, in
#: characters: what is read of one line at a time (memory stays bounded).
MAX_LINE = 1_000_000


def token_lines(path: PathLike) -> Iterator[tuple[int, list[str]]]:
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


#: Suffixes of (extended) XYZ files: a count of atoms, a comment line, then
#: a line per atom, frame after frame.
XYZ_SUFFIXES = ('.xyz', '.extxyz')

#: The fewest bytes an atom line of an XYZ file takes: 'H 0 0 0' and its
#: line end.
XYZ_ATOM_BYTES = 8


def check_xyz_counts(path: PathLike) -> None:
    """The atom count each frame of an XYZ file declares, checked against
    the bytes left after it (:data:`XYZ_ATOM_BYTES` an atom at least), before
    ASE's reader allocates what it declares (a 50-byte file declaring 10^8
    atoms holds it for minutes): a ValueError naming the line. A line that
    is not a count is left to ASE's reader to judge."""
    size = os.path.getsize(path)
    number = 0
    with open(path, 'rb') as f:
        while (line := f.readline(MAX_LINE + 1)):
            number += 1
            if not line.strip():
                continue
            try:
                count = int(line)
            except ValueError:
                return
            room = (size - f.tell()) // XYZ_ATOM_BYTES
            if count > room:
                raise ValueError(f'{path} line {number}: declares {count} atoms, but the '
                                 f'{size - f.tell()} bytes after it hold at most {room}')
            for _ in range(count + 1):   # its comment line and atoms
                if not f.readline(MAX_LINE + 1):
                    return
                number += 1


def check_finite(path, where, values):
    """``values`` (floats), or ValueError naming ``where`` if one is not
    finite (nan, inf, or beyond the float64 range such as 1e400)."""
    if not np.isfinite(values).all():
        raise ValueError(f'{path} {where}: coordinates must be finite numbers, got '
                         f'{values}')
    return values


def parse_numbers(path, number, tokens, what, kind=int):
    """``tokens`` as ``kind`` (int or float), or ValueError naming the line
    and ``what``."""
    try:
        return [kind(t) for t in tokens]
    except ValueError:
        raise ValueError(f'{path} line {number}: expected {what}, got '
                         f'{" ".join(tokens)!r}') from None


def check_index(path, number, i, natoms):
    """ValueError naming line ``number`` if index ``i`` is not in ``range(natoms)``."""
    if not 0 <= i < natoms:
        raise ValueError(f'{path} line {number}: index {i} out of range '
                         f'({natoms} points, 0-based)')


def read_edges(path: PathLike, natoms: int) -> np.ndarray:
    """An edge list: (K, 2) int array from two 0-based indices per line.

    ValueError with the line number on anything else, an index out of
    ``range(natoms)``, a spring from a point to itself or a repeated pair.
    """
    springs, seen = [], {}
    for number, tokens in token_lines(path):
        pair = parse_numbers(path, number, tokens, 'two integer indices')
        if len(pair) != 2:
            raise ValueError(f'{path} line {number}: expected two integer '
                             f'indices, got {len(pair)}')
        for i in pair:
            check_index(path, number, i, natoms)
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
    ValueError with the line number on a non-integer, one out of range or
    one given before."""
    seen = {}
    for number, tokens in token_lines(path):
        for i in parse_numbers(path, number, tokens, 'integer point indices'):
            check_index(path, number, i, natoms)
            if i in seen:
                raise ValueError(f'{path} line {number}: point {i} repeats line {seen[i]}')
            seen[i] = number
    return list(seen)


def coordinates(x):
    """x, y, z as text, each the shortest that reads back as its float."""
    return ' '.join(repr(float(c)) for c in x)


def original_text(path):
    """The text of ``path`` as it is: line endings kept, a UTF-8 byte-order
    mark apart: (mark or '', the rest)."""
    with open(path, encoding='utf-8', newline='') as f:
        text = f.read()
    mark = text[:1] if text.startswith('\ufeff') else ''
    return mark, text[len(mark):]


def number_text(old: str, value: float) -> str:
    """``old`` (a number's text in a file) if it reads as ``value``, else
    the shortest text that reads back as ``value`` exactly (``repr``)."""
    return old if float(old) == value else repr(float(value))
