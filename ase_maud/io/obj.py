"""Wavefront OBJ nets: read (points, coincident ones merged; springs from the
faces, polylines and curves of degree 1) and written back into the original
text (the format as :mod:`ase_maud.io` describes it)."""

from __future__ import annotations

import re
import warnings
from io import StringIO

import numpy as np

from ase_maud.io.mesh import mesh_cells
from ase_maud.io.net_data import MERGE_TOLERANCE, NetData, PathLike, merge_coincident
from ase_maud.io.text import (
    check_finite,
    coordinates,
    number_text,
    original_text,
    parse_numbers,
    token_lines,
)
from ase_maud.physics.topology import unique_pairs

#: OBJ curve types (``cstype``, after an optional ``rat``) read, with
#: ``deg 1``: polylines through their control points.
CURVE_TYPES = ('bspline', 'bezier')


def read_obj(path: PathLike) -> NetData:
    """Points, springs and faces of an OBJ file (see the module docstring).

    Springs: the edges of every face (``f``), the segments of every polyline
    (``l``) and of every curve of degree 1 (``curv``), each undirected pair
    once, in order of appearance. Vertices closer than
    :data:`MERGE_TOLERANCE` times the diagonal of their bounding box are one
    point (:func:`merge_coincident`).
    """
    return _obj_file(path, with_rows=False)[0]


def _statements(path):
    """(line number, tokens, whether continued) of an OBJ file's statements;
    a line that ends in a backslash goes on in the next (numbered as its
    first line)."""
    held = None
    for number, tokens in token_lines(path):
        if held is not None:
            number, tokens = held[0], held[1] + tokens
        continued, held = held is not None, None
        if tokens[-1].endswith('\\'):
            tokens[-1] = tokens[-1][:-1]
            held = (number, [t for t in tokens if t])
        else:
            yield number, tokens, continued
    if held is not None and held[1]:
        yield *held, True


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
    parse_numbers(path, number, rest[:2], "'curv u0 u1 v1 v2 ...' with numbers u0 u1", float)
    if len(rest) < 4:
        raise ValueError(f"{path} line {number}: a 'curv' needs its parameters u0 u1 "
                         f'and at least 2 vertex indices, got {len(rest)} numbers')
    return rest[2:]


def _obj_file(path, with_rows=True):
    """The net of an OBJ file (:class:`NetData`), the point of every ``v``
    statement (:func:`merge_coincident`) and the line numbers of the ``v``
    statements: by :func:`_plain_obj_file` where the file is plain, else
    statement by statement (:func:`_any_obj_file`, whose errors name the
    line)."""
    return _plain_obj_file(path, with_rows) or _any_obj_file(path)


#: Statements that :func:`_plain_obj_file` skips (they hold no point or spring).
_SKIPPED = frozenset(('vt', 'vn', 'vp', 'g', 'o', 's', 'usemtl', 'mtllib'))


def _plain_obj_file(path, with_rows=True):
    """:func:`_obj_file` by numpy, for a plain OBJ file (``v x y z`` lines,
    ``f`` and ``l`` lines of indices, the statements of :data:`_SKIPPED`,
    comments; nothing continued, no curves): about 4 times faster than
    statement by statement on a large mesh. None where the file is not plain
    or anything is wrong in it (the statement-by-statement reader then says
    what and where)."""
    try:
        with open(path, encoding='utf-8-sig') as f:
            text = f.read()
    except (UnicodeDecodeError, OSError):
        return None
    if '\\' in text:
        return None
    if '#' in text:
        text = re.sub(r'#[^\n]*', '', text)   # a comment runs to the end of its line
    keywords = re.findall(r'^[ \t]*(\S+)', text, re.M)
    if set(keywords) - _SKIPPED - {'v', 'f', 'l'}:
        return None
    statements = np.array(keywords)
    kinds: dict[str, list[tuple[int, str]]] = {}
    for keyword in ('v', 'f', 'l'):
        found = re.findall(rf'^[ \t]*{keyword}[ \t]+(\S[^\n]*)', text, re.M)
        where = np.flatnonzero(statements == keyword)   # statement numbers, in order
        if len(found) != len(where):   # a statement without its numbers
            return None
        kinds[keyword] = list(zip(where.tolist(), found, strict=True))
    if not kinds['v']:
        return None
    count = len(kinds['v'])
    xyz = _numbers(' '.join(rest for _, rest in kinds['v']), float)
    if xyz is None or xyz.size != 3 * count or not np.isfinite(xyz).all():
        return None
    vertices = xyz.reshape(-1, 3)
    v_before = np.cumsum(statements == 'v')   # v statements up to each statement
    chains = []   # (statement numbers, rings or polylines of 0-based vertex indices, faces?)
    for keyword in ('f', 'l'):
        for size, lines in _by_count(kinds[keyword]).items():
            numbers = np.array([n for n, _ in lines])
            joined = ' '.join(rest for _, rest in lines)
            if '/' in joined:
                joined = re.sub(r'/\S*', '', joined)
            raw = _numbers(joined, np.int64)
            if raw is None or raw.size != size * len(lines):
                return None
            raw = raw.reshape(-1, size)
            if (raw == 0).any() or size < (3 if keyword == 'f' else 2):
                return None
            index = np.where(raw > 0, raw - 1, v_before[numbers][:, None] + raw)
            if (index < 0).any() or (index >= count).any():
                return None
            chains.append((numbers, index, keyword == 'f'))
    point_of, points = merge_coincident(vertices)
    edges, order, faces = [np.zeros((0, 2), dtype=np.int64)], [np.zeros(0)], []
    for numbers, index, face in chains:
        ring = np.concatenate([index, index[:, :1]], axis=1) if face else index
        pairs = np.stack([point_of[ring[:, :-1]], point_of[ring[:, 1:]]], axis=-1)
        if (pairs[..., 0] == pairs[..., 1]).any():
            return None
        edges.append(pairs.reshape(-1, 2))
        steps = np.arange(pairs.shape[1]) / (pairs.shape[1] + 1)
        order.append((numbers[:, None] + steps).ravel())
        if face:
            faces.append((numbers, point_of[index]))
    edges = np.concatenate(edges)
    if len(chains) > 1:   # springs in order of appearance, as statement by statement
        edges = edges[np.argsort(np.concatenate(order), kind='stable')]
    springs = edges[np.sort(unique_pairs(edges)[1])]
    if len(faces) == 1:
        rings = faces[0][1]
    else:
        listed = sorted((n, ring) for numbers, index in faces
                        for n, ring in zip(numbers.tolist(), index.tolist(), strict=True))
        rings = [ring for _, ring in listed]
    rows = None
    if with_rows:   # the line number of each v statement
        newlines = np.flatnonzero(np.frombuffer(text.encode('utf-32-le'), np.uint32) == 10)
        starts = [m.start() for m in re.finditer(r'^[ \t]*v[ \t]+\S', text, re.M)]
        rows = (np.searchsorted(newlines, starts) + 1).tolist()
    return NetData(points, springs, rings, []), point_of, rows


def _numbers(text, dtype):
    """The numbers of ``text`` (separated by white space) as a 1-D array of
    ``dtype`` parsed in C, or None where any is not one."""
    with warnings.catch_warnings():
        warnings.simplefilter('error')   # numpy warns, and stops, at text it cannot read
        try:
            return np.fromstring(text, dtype=dtype, sep=' ')
        except (DeprecationWarning, ValueError):
            return None


def _by_count(lines):
    """``lines`` ((line number, text) pairs) grouped by their count of tokens."""
    groups: dict[int, list[tuple[int, str]]] = {}
    for number, rest in lines:
        groups.setdefault(len(rest.split()), []).append((number, rest))
    return groups


def _any_obj_file(path):
    """:func:`_obj_file` statement by statement."""
    vertices, rows, refs = [], [], []   # refs: (line, element kind, 0-based indices)
    curve = (None, None)   # cstype and deg of the curves that follow
    for number, tokens, continued in _statements(path):
        keyword, rest = tokens[0], tokens[1:]
        if keyword == 'v' and continued:
            raise ValueError(f"{path} line {number}: a 'v' statement goes on in the next "
                             "line (ends in '\\'); its coordinates are written back in "
                             'place, so each must be on one line: join them')
        if keyword == 'v':
            xyz = parse_numbers(path, number, rest[:3], "'v x y z' with numbers", float)
            if len(rest) < 3:
                raise ValueError(f"{path} line {number}: expected 'v x y z', "
                                 f'got {len(rest)} coordinates')
            vertices.append(check_finite(path, f'line {number}', xyz))
            rows.append(number)
        elif keyword == 'cstype':
            curve = (rest[-1] if rest else '', curve[1])
        elif keyword == 'deg':
            curve = (curve[0], parse_numbers(path, number, rest[:1] or ['?'], 'a degree')[0])
        elif keyword in ('f', 'l', 'curv'):
            least = 3 if keyword == 'f' else 2
            if keyword == 'curv':
                rest = _curve_indices(path, number, rest, curve)
            if len(rest) < least:
                raise ValueError(f'{path} line {number}: a {keyword!r} needs '
                                 f'at least {least} vertex indices, got {len(rest)}')
            raw = parse_numbers(path, number, [t.split('/')[0] for t in rest],
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


#: An OBJ ``v`` statement's keyword and x, y, z with the space around them.
_VERTEX = re.compile(r'(\s*v\s+)([^\s#]+)(\s+)([^\s#]+)(\s+)([^\s#]+)')


def obj_text(atoms, like):
    """The OBJ text of ``atoms``: ``like`` as it is but for the coordinates
    that moved, or points, the faces ``atoms.info['faces']`` as ``f`` lines
    and the other springs as ``l`` lines."""
    if like is None:
        lines = [f'v {coordinates(x)}' for x in atoms.positions]
        for name, cells in mesh_cells(atoms.info.get('faces'), atoms.calc.springs):
            keyword = 'l' if name == 'line' else 'f'
            lines += [f'{keyword} ' + ' '.join(map(str, ring)) for ring in (cells + 1).tolist()]
        return '\n'.join(['# written by ase_maud', *lines]) + '\n'
    net, point_of, rows = _obj_file(like)
    if len(net.positions) != len(atoms):
        raise ValueError(f'{like} has {len(net.positions)} points ({len(point_of)} '
                         f'vertices, coincident ones merged), the net {len(atoms)}')
    mark, text = original_text(like)
    lines = list(StringIO(text, newline=''))
    for row, point in zip(rows, point_of, strict=True):
        line = lines[row - 1]
        match = _VERTEX.match(line)
        new = [number_text(match[k], x) for k, x in zip((2, 4, 6), atoms.positions[point],
                                                          strict=True)]
        lines[row - 1] = (match[1] + new[0] + match[3] + new[1] + match[5] + new[2]
                          + line[match.end():])
    return mark + ''.join(lines)
