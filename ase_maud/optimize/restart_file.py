"""The restart file of a Maud run: written after every step, cheap, crash-safe,
and enough to carry on exactly.

Two files. ``NAME`` is JSON: the step, the run monitor's state, the step
rule's scalars (gamma, momentum count, the last point's merit and noise, the
model's learnt state, a saddle search's predicted energy change), under a
cell filter its original cell (the filter's coordinates are measured from
it; ASE's recipe makes a new filter on the last frame), and which rows of the
arrays file hold what. ``NAME.arrays`` holds the arrays as raw
float64 rows of 3N numbers each:

- two state slots, used in turn, of three rows (the positions, the last
  point and its forces) and, for a saddle search, one row per mode it keeps
  (``modes`` in ``NAME``: the ``order`` it follows, signed as followed, then
  on the springs model the other lowest modes of its last step), then one
  row per array the model keeps in what it has learnt (``learnt`` in
  ``NAME``: the global model's ``built``, where its ``P`` was built);
- pair slots of two rows (an L-BFGS pair ``s``, ``y``), each pair written
  once, into a slot the committed JSON does not name (at most ``memory + 1``
  slots are ever used).

A step writes its rows (a few times 3N numbers, not the whole memory), then
replaces ``NAME`` atomically (a temporary file in the same folder, then
``os.replace``): a process killed at any moment leaves ``NAME`` naming rows
that were whole before it was replaced (the operating system keeps what was
written), so the files hold the old step or the new one, never a mixture.
Against a crash of the machine itself both files are also flushed to disk
(``fsync``) at most every :data:`SYNC_SECONDS`, which bounds what a crash can
take; ``NAME`` holds a CRC-32 of every row group it names, so rows that never
reached the disk are found on reading, never taken. The momentum ``v`` is the
positions minus the last point and is not stored.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
import zlib
from pathlib import Path
from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.checks import as_number
from ase_maud.errors import RestartFileError
from ase_maud.files.atomic_replace import remove_leftovers, replace_text
from ase_maud.optimize.state import MaudState, Point
from ase_maud.physics.topology import fixed_atoms

#: The version of the layout; a file of another one is refused by name.
FORMAT = 'maud-restart-7'
#: Rows per state slot before a saddle search's modes: positions, the last
#: point, its forces.
STATE_ROWS = 3
#: Longest time between two flushes of the files to disk (``fsync``), from
#: the first write on: what a crash of the machine (not of the process) can
#: take. A flush waits for the disk (milliseconds to a tenth of a second for
#: the megabytes of a large scene), more than a whole step of a small one;
#: rows overwritten between two flushes reach the disk once.
SYNC_SECONDS = 10.0


class RestartFile:
    """Reads and writes the restart files of one run (module docstring);
    ``path`` is the JSON file, ``path + '.arrays'`` the rows; ``modes``: the
    modes the run keeps (a saddle search's
    :attr:`~ase_maud.optimize.strategy.Saddle.kept_modes`; None for other targets),
    which fixes the size of a state slot."""

    def __init__(self, path: str | os.PathLike, modes: int | None = None,
                 learnt: tuple[str, ...] = ()):
        self.path = Path(path)
        self.arrays = self.path.with_name(self.path.name + '.arrays')
        self.modes, self.learnt = modes, tuple(learnt)
        self._slot_rows = STATE_ROWS + (modes or 0) + len(self.learnt)
        remove_leftovers(self.path)   # of runs killed while replacing it
        self._slot = 1   # the state slot written last
        self._synced = time.monotonic()   # of the last fsync (or of the start)
        # id(s) of each pair the committed file names -> (s, its pair slot, the
        # CRC-32 of its rows); s is kept so that its id cannot be reused
        self._pairs: dict[int, tuple[np.ndarray, int, int]] = {}

    def write(self, step: int, x: np.ndarray, state: MaudState,
              monitor: dict[str, Any], fmax_now: float, scene: dict[str, Any],
              orig_cell: np.ndarray | None = None) -> None:
        """Save the run at ``step``: positions ``x`` (N, 3), the step rule's
        ``state`` (whose ``last`` is set, and ``modes`` for a saddle search),
        the monitor's state, the scene's :func:`signature` and, under a cell
        filter, its original cell (3, 3), which its coordinates are
        relative to."""
        rows = x.size
        self._slot = 1 - self._slot
        kept = {id(s): self._pairs[id(s)] for s, _ in state.pairs if id(s) in self._pairs}
        taken = {slot for _, slot, _ in self._pairs.values()}
        free = (slot for slot in itertools.count() if slot not in taken)
        sync = time.monotonic() - self._synced >= SYNC_SECONDS
        with open(self.arrays, 'r+b' if self.arrays.exists() else 'w+b') as handle:
            first = self._slot * self._slot_rows
            state_crc = self._write_rows(handle, first, rows,
                                         [x, state.last.x, state.last.forces])
            modes_crc = self._write_rows(handle, first + STATE_ROWS, rows,
                                         [] if self.modes is None else list(state.modes))
            learnt_crc = self._write_rows(handle, first + STATE_ROWS + (self.modes or 0), rows,
                                          [state.model[name] for name in self.learnt])
            for s, y in state.pairs:
                if id(s) not in kept:
                    slot = next(free)
                    kept[id(s)] = s, slot, self._write_rows(
                        handle, 2 * self._slot_rows + 2 * slot, rows, [s, y])
            if sync:
                handle.flush()
                os.fsync(handle.fileno())
        self._pairs = kept
        document = {
            'format': FORMAT, 'rows': rows, 'step': step, 'slot': self._slot,
            'pairs': [kept[id(s)][1] for s, _ in state.pairs],
            'crc': {'state': state_crc, 'modes': modes_crc, 'learnt': learnt_crc,
                    'pairs': [kept[id(s)][2] for s, _ in state.pairs]},
            'gamma': state.gamma, 'k': state.k, 'moving': state.v is not None,
            'merit': state.last.merit, 'noise': state.last.noise,
            'model': {name: value for name, value in state.model.items()
                      if name not in self.learnt},
            'learnt': list(self.learnt), 'modes': self.modes, 'predicted': state.predicted,
            'monitor': _plain(monitor), 'fmax_now': fmax_now, 'scene': scene,
            'orig_cell': None if orig_cell is None else _plain(orig_cell)}
        replace_text(self.path, json.dumps(document), sync)
        if sync:
            self._synced = time.monotonic()

    def read(self) -> dict[str, Any]:
        """What :meth:`write` saved: ``step``, ``x`` (N, 3), ``state`` (a
        :class:`MaudState`), ``monitor``, ``fmax_now``, ``scene``,
        ``orig_cell`` (an array (3, 3) or None). A file of another
        layout, a damaged field, a file of a run that follows other modes
        (see :attr:`modes`), or one whose arrays file is missing, short or
        damaged is a ValueError naming it (and the field)."""
        try:
            text = self.path.read_text()
        except (OSError, ValueError) as error:
            raise RestartFileError(f'restart file {str(self.path)!r} cannot be read: '
                                   f'{error}') from None
        try:
            document = json.loads(text)
        except (ValueError, RecursionError) as error:
            raise RestartFileError(f'Could not decode restart file {str(self.path)!r} '
                                   f'as JSON ({error}); delete it and its arrays '
                                   'file') from None
        if not isinstance(document, dict) or document.get('format') != FORMAT:
            held = document.get('format') if isinstance(document, dict) else None
            raise RestartFileError(f'restart file {str(self.path)!r} was not written by '
                                   f'this version of Maud (format {held!r}, this version '
                                   f'reads {FORMAT!r}); delete it and its arrays file')
        if (damaged := _damaged_field(document)) is not None:
            raise RestartFileError(f'restart file {str(self.path)!r} is damaged: {damaged}; '
                                   'delete it and its arrays file')
        if document['learnt'] != list(self.learnt):
            raise RestartFileError(f'restart file {str(self.path)!r} is of another run: '
                                   f"'learnt' {document['learnt']!r} in it, "
                                   f"{list(self.learnt)!r} in this run (the arrays its model "
                                   "keeps); give that run's model, or delete it")
        if document['modes'] != self.modes:
            raise RestartFileError(f'restart file {str(self.path)!r} is of another run: '
                                   f"'modes' {document['modes']!r} in it, {self.modes!r} in "
                                   'this run (the modes a saddle search keeps: its order, '
                                   'and on the springs model the next lowest; null for other '
                                   "targets); give that run's target, order and model, or "
                                   'delete it')
        rows, slot, pairs = document['rows'], document['slot'], document['pairs']
        size, modes = self._slot_rows, self.modes or 0
        last_row = max((slot + 1) * size, 2 * size + 2 * (max(pairs) + 1) if pairs else 0)
        needed = last_row * rows * 8
        if not self.arrays.is_file() or self.arrays.stat().st_size < needed:
            raise RestartFileError(f'restart file {str(self.path)!r}: its arrays file '
                                   f'{str(self.arrays)!r} is missing or short; delete both')
        table = np.fromfile(self.arrays, dtype=np.float64, count=last_row * rows
                            ).reshape(-1, rows)
        crc = document['crc']
        groups = [('the positions, the last point and its forces', slot * size,
                   STATE_ROWS, crc['state'])]
        if modes:
            groups.append(("the saddle search's modes, 'modes'", slot * size + STATE_ROWS,
                           modes, crc['modes']))
        if self.learnt:
            groups.append(("the arrays the model keeps, 'learnt'",
                           slot * size + STATE_ROWS + modes, len(self.learnt), crc['learnt']))
        groups += [(f'pair slot {p}', 2 * size + 2 * p, 2, c)
                   for p, c in zip(pairs, crc['pairs'], strict=True)]
        for what, first, count, expected in groups:
            where = (f'restart file {str(self.path)!r}: rows {first}-{first + count - 1} '
                     f'of {str(self.arrays)!r}')
            if zlib.crc32(table[first:first + count].tobytes()) != expected:
                raise RestartFileError(f'{where} are not what it wrote ({what}; a crash of the '
                                       'machine before they reached the disk?); delete both files')
            if not np.isfinite(table[first:first + count]).all():
                raise RestartFileError(f'{where} hold non-finite numbers ({what}); delete both '
                                       'files')
        x, last_x, forces = (table[slot * size + k].reshape(-1, 3).copy()
                             for k in range(STATE_ROWS))
        saddle_modes = table[slot * size + STATE_ROWS:slot * size + STATE_ROWS + modes
                             ].reshape(modes, rows // 3, 3).copy()
        kept = {name: table[slot * size + STATE_ROWS + modes + k].reshape(-1, 3).copy()
                for k, name in enumerate(self.learnt)}
        state = MaudState(
            gamma=float(document['gamma']), k=document['k'],
            v=x - last_x if document['moving'] else None,
            last=Point(last_x, float(document['merit']), forces, float(document['noise'])),
            pairs=[(table[2 * size + 2 * p].reshape(-1, 3).copy(),
                    table[2 * size + 2 * p + 1].reshape(-1, 3).copy())
                   for p in pairs],
            model={**document['model'], **kept},
            modes=None if self.modes is None else saddle_modes,
            predicted=None if document['predicted'] is None else float(document['predicted']))
        self._slot = slot
        self._pairs = {id(s): (s, p, c) for (s, _), p, c
                       in zip(state.pairs, pairs, crc['pairs'], strict=True)}
        return {'step': document['step'], 'x': x, 'state': state,
                'monitor': document['monitor'], 'fmax_now': float(document['fmax_now']),
                'scene': document['scene'],
                'orig_cell': (None if document['orig_cell'] is None
                              else np.array(document['orig_cell'], dtype=float))}

    @staticmethod
    def _write_rows(handle, first: int, rows: int, arrays: list[np.ndarray]) -> int:
        """Write ``arrays`` (``rows`` numbers each) from row ``first`` on;
        return the CRC-32 of what was written."""
        data = b''.join(np.ascontiguousarray(array, dtype=np.float64).tobytes()
                        for array in arrays)
        handle.seek(first * rows * 8)
        handle.write(data)
        return zlib.crc32(data)


def _whole(value: Any, low: int = 0) -> bool:
    """``value`` is an int (JSON's integers; not a bool) >= ``low``."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _positive(value: Any) -> bool:
    number = as_number(value)
    return number is not None and number > 0


#: What each field of the JSON file must hold, in words and as a test.
FIELDS: dict[str, tuple[str, Any]] = {
    'rows': ('a positive multiple of 3', lambda v: _whole(v, 3) and v % 3 == 0),
    'step': ('a whole number >= 0', _whole),
    'slot': ('0 or 1', lambda v: _whole(v) and v <= 1),
    'pairs': ('a list of distinct whole numbers >= 0',
              lambda v: isinstance(v, list) and all(map(_whole, v)) and len(set(v)) == len(v)),
    'crc': ('{"state": a CRC-32, "modes": a CRC-32, "learnt": a CRC-32, "pairs": one per pair}',
            lambda v: isinstance(v, dict) and _whole(v.get('state')) and _whole(v.get('modes'))
            and _whole(v.get('learnt'))
            and isinstance(v.get('pairs'), list) and all(map(_whole, v['pairs']))),
    'gamma': ('a positive finite number', _positive),
    'k': ('a whole number >= 0', _whole),
    'moving': ('true or false', lambda v: isinstance(v, bool)),
    'merit': ('a finite number', lambda v: as_number(v) is not None),
    'noise': ('a finite number >= 0', lambda v: as_number(v) == 0 or _positive(v)),
    'model': ('an object of positive finite numbers',
              lambda v: isinstance(v, dict) and all(map(_positive, v.values()))),
    'learnt': ('a list of names (the arrays the model keeps)',
               lambda v: isinstance(v, list) and all(isinstance(n, str) for n in v)),
    'modes': ('null or a whole number >= 0 (the modes a saddle search keeps)',
              lambda v: v is None or _whole(v)),
    'predicted': ('null or a finite number', lambda v: v is None or as_number(v) is not None),
    'monitor': ('an object', lambda v: isinstance(v, dict)),
    'fmax_now': ('a number >= 0',
                 lambda v: as_number(v) == 0 or _positive(v) or v == math.inf),
    'scene': ('an object', lambda v: isinstance(v, dict)),
    'orig_cell': ('null or 3 rows of 3 finite numbers (a cell filter\'s original cell)',
                  lambda v: v is None or (isinstance(v, list) and len(v) == 3 and all(
                      isinstance(row, list) and len(row) == 3
                      and all(as_number(c) is not None for c in row) for row in v))),
}


def _damaged_field(document: dict[str, Any]) -> str | None:
    """The first field of a restart file's JSON that is missing or not what
    :data:`FIELDS` says, in words; or None."""
    for key, (what, valid) in FIELDS.items():
        if key not in document:
            return f'it has no {key!r}'
        if not valid(document[key]):
            return f'{key!r} must be {what}, got {document[key]!r}'
    if len(document['crc']['pairs']) != len(document['pairs']):
        crc, pairs = len(document['crc']['pairs']), len(document['pairs'])
        return f'"crc" names {crc} pairs, "pairs" {pairs}'
    return None


def signature(atoms: Atoms, potential: Any = None) -> dict[str, Any]:
    """What a run's files are checked against when it is resumed onto
    ``atoms``: the number of points, the fixed ones and, with a ``potential``
    (a :class:`~ase_maud.calculator.potential.MaudPotential`), its springs, ``a``, ``Q``,
    ``dim``, force densities ``q`` (in the order of the sorted springs) and
    loads; plain values, long lists as a count and a CRC-32."""
    fixed = np.flatnonzero(fixed_atoms(atoms))
    scene = {'points': len(atoms), 'fixed points': len(fixed),
             'fixed points crc': zlib.crc32(fixed.astype(np.int64).tobytes())}
    if potential is not None:
        pairs, first = np.unique(np.sort(potential.springs, axis=1), axis=0,
                                 return_index=True)
        q = np.broadcast_to(potential.stiffnesses, len(potential.springs))[first]
        loads = (np.zeros((len(atoms), 3)) if potential.loads is None
                 else potential.loads)
        scene.update({'springs': len(pairs),
                      'springs crc': zlib.crc32(pairs.astype(np.int64).tobytes()),
                      'a': potential.a, 'Q': potential.Q, 'dim': potential.dim,
                      'force densities': len(q), 'force densities crc': _crc(q),
                      'loads': int(np.count_nonzero(loads.any(axis=1))),
                      'loads crc': _crc(loads)})
    return scene


def _crc(values: np.ndarray) -> int:
    """CRC-32 of ``values`` as contiguous float64."""
    return zlib.crc32(np.ascontiguousarray(values, dtype=np.float64).tobytes())


def difference(held: dict[str, Any], given: dict[str, Any],
               every: bool = False) -> str | None:
    """The first way the scene of a file (``held``) and the atoms given
    differ, in words (None if they agree on every key both have; with
    ``every``, as a restart file's scene, which its run wrote whole, also
    if ``held`` lacks a key of ``given``)."""
    missing = [key for key in given if key not in held] if every else []
    if missing:
        return (f'its scene has no {missing[0]!r} (the atoms given have: '
                f'{given[missing[0]]!r}; a file damaged by hand, or of a run on '
                'another calculator)')
    for key in held:
        if key in given and held[key] != given[key]:
            what = key.removesuffix(' crc')
            if key.endswith(' crc'):
                return f'its {what} are other ones (as many: {held[what]})'
            return f'{key} {held[key]!r} in it, {given[key]!r} in the atoms given'
    return None


def _plain(value: Any) -> Any:
    """``value`` with numpy arrays and scalars as lists and floats (JSON)."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(item) for item in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
