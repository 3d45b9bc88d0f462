"""COMPAS JSON nets (meshes and networks, COMPAS 1.x and 2.x): read (points,
springs, anchors, compas_fd's force densities and loads) and written back
into the original text, or as a COMPAS 2.x graph (the format as
:mod:`ase_maud.io` describes it)."""

from __future__ import annotations

import itertools
import json
import os
import re
import uuid
from typing import Any

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms

from ase_maud.checks import as_number, check
from ase_maud.io.net_data import NetData, PathLike
from ase_maud.io.text import check_finite, number_text, original_text
from ase_maud.physics.topology import default_a, fixed_atoms

#: Vertex (node) attributes of COMPAS data that fix a point when true.
ANCHOR_ATTRIBUTES = ('is_anchor', 'is_fixed')


#: Vertex (node) attributes of COMPAS data that hold a load (compas_fd's).
LOAD_ATTRIBUTES = ('px', 'py', 'pz')


#: Vertex (node) attributes that :func:`compas_text` gives each support: its
#: reaction (:mod:`ase_maud.form.member_forces`).
REACTION_ATTRIBUTES = ('rx', 'ry', 'rz')


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
            if isinstance(value, int) and as_number(value) is None:   # 400 digits
                raise ValueError(f'{path}: vertex {key} has {axis} = {str(value)[:20]}... '
                                 f'({len(str(value))} digits), beyond the float64 range')
            xyz.append(float(value))
        positions.append(check_finite(path, f'vertex {key}', xyz))
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
                     ) -> dict[tuple[int, int], list[dict[str, Any]]]:
    """The attribute dicts of the edges of COMPAS ``data`` (the document's
    own, to read or change), by sorted pair of point indices: a graph's
    ``edge[u][v]``, a mesh's ``edgedata`` (keys ``"(u, v)"`` or ``"u-v"``);
    more than one where the file lists an edge both ways."""
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
            found.setdefault((min(i, j), max(i, j)), []).append(attributes)
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


def _edge_q(path, listed, defaults, u, v):
    """``q`` of the edge ``u``-``v`` (vertex keys) whose attribute dicts are
    ``listed`` (one per time the file lists it): a ValueError naming the
    edge and both values if two say different ones."""
    values = [_compas_value(path, f'edge {u}-{v}', 'q', a, defaults, 1.0) for a in listed]
    if any(value != values[0] for value in values):
        raise ValueError(f'{path}: edge {u}-{v} is listed both ways with different q '
                         f'({values[0]!r} and {next(x for x in values if x != values[0])!r}); '
                         'give it once, or one q')
    return values[0]


def _compas_forces(path, data, springs):
    """``q`` (K,) and loads (N, 3) a COMPAS document says (1 and 0 where it
    says nothing), and whether it says anything of each."""
    points, vertex_defaults = _compas_points(path, data)
    keys = {str(k): n for n, k in enumerate(points)}
    edge_defaults = data.get('default_edge_attributes', data.get('dea', {})) or {}
    edges, names = _edge_attributes(data, keys), list(points)
    q = np.array([_edge_q(path, edges.get((min(i, j), max(i, j)), [{}]), edge_defaults,
                          names[i], names[j]) for i, j in springs])
    loads = np.array([[_compas_value(path, f'vertex {key}', name, attributes, vertex_defaults, 0.0)
                       for name in LOAD_ATTRIBUTES] for key, attributes in points.items()])
    said_q = 'q' in edge_defaults or any('q' in a for both in edges.values() for a in both)
    said_loads = any(name in vertex_defaults or any(name in a for a in points.values())
                     for name in LOAD_ATTRIBUTES)
    return q.reshape(len(springs)), loads.reshape(-1, 3), said_q, said_loads


#: The key, in a COMPAS document's graph (mesh) ``attributes``, of the
#: ``a`` and ``Q`` :func:`compas_text` wrote with: a file's ``q`` is the
#: force density ``Q q``, so a net read back is the net written.
PARAMETERS_KEY = 'ase_maud'


def _stored_parameters(path, data) -> dict[str, float]:
    """The ``a`` and ``Q`` a COMPAS document stores under
    :data:`PARAMETERS_KEY` (checked), or {}."""
    attributes = data.get('attributes')
    stored = attributes.get(PARAMETERS_KEY) if isinstance(attributes, dict) else None
    if stored is None:
        return {}
    if not isinstance(stored, dict) or not set(stored) <= {'a', 'Q'}:
        raise ValueError(f'{path}: attributes.{PARAMETERS_KEY} must be an object of a and '
                         f'Q, got {stored!r}')
    try:
        return {name: check(name, float(value) if isinstance(value, int) else value)
                for name, value in stored.items()}
    except ValueError as error:
        raise ValueError(f'{path}: attributes.{PARAMETERS_KEY}: {error}') from None


def read_compas_forces(path: PathLike, springs: np.ndarray) -> dict[str, Any]:
    """The force densities ``q`` of ``springs`` (as :func:`read_compas` gives
    them) and the loads of a COMPAS JSON file, as calculator parameters:
    only those the file says anything of (see the module docstring); with
    the ``a`` and ``Q`` it stores (:data:`PARAMETERS_KEY`), ``q`` is the
    file's divided by that ``Q``."""
    _, data = _compas_data(path)
    q, loads, said_q, said_loads = _compas_forces(path, data, springs)
    stored = _stored_parameters(path, data)
    q = q / stored.get('Q', 1.0)
    return {**({'q': q} if said_q else {}), **({'loads': loads} if said_loads else {}),
            **stored}


def _parameters(atoms) -> dict[str, float]:
    """The ``a`` and ``Q`` of ``atoms``' calculator that a COMPAS file must
    store to be read back as written: none where reading gives them anyway
    (``Q = 1`` and ``a`` the default of the net, :func:`ase_maud.physics.topology.default_a`),
    else both."""


    potential = atoms.calc.potential
    a, Q = float(potential.a), float(potential.Q)
    read = Atoms(positions=atoms.positions)   # as read back: the anchors alone held
    read.set_constraint(FixAtoms(mask=fixed_atoms(atoms)))
    if Q == 1.0 and a == default_a(read, potential.springs):
        return {}
    return {'a': a, 'Q': Q}


def _set_parameters(data, parameters) -> None:
    """Store ``parameters`` (:func:`_parameters`) in COMPAS ``data``'s
    attributes (or drop an earlier run's where there are none)."""
    if not isinstance(data.get('attributes'), dict):
        if not parameters:
            return
        data['attributes'] = {}
    if parameters:
        data['attributes'][PARAMETERS_KEY] = parameters
    else:
        data['attributes'].pop(PARAMETERS_KEY, None)


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


def compas_text(atoms, like, result=None):
    """The COMPAS JSON text of ``atoms``: ``like`` as it is but for the
    x, y, z that moved, or a COMPAS 2.x graph. A file whose ``q``, loads or
    supports (``is_anchor``) the net changes, or with a vertex that takes a
    coordinate from the defaults and moves in it, is written anew, without
    its layout; so is one given a ``result`` (a
    :class:`~ase_maud.form.member_forces.FormResult` of ``atoms``), whose member forces
    become edge attributes ``q`` (``Q q``, force per length), ``force``
    (``Q q L``, tension positive) and ``length``, and whose reactions vertex
    attributes ``rx``, ``ry``, ``rz`` of the supports."""
    potential = atoms.calc.potential
    q = potential.Q * np.broadcast_to(potential.stiffnesses, len(potential.springs))
    loads = np.zeros((len(atoms), 3)) if potential.loads is None else potential.loads
    if like is None:
        document = _compas_graph(atoms, q, loads)
        _set_parameters(document['data'], _parameters(atoms))
        if result is not None:
            _set_results(like, document['data'], result)
        return json.dumps(document)
    places = itertools.count()
    document, data = _compas_data(like, number=_placed(places))
    points, defaults = _compas_points(like, data)
    if len(points) != len(atoms):
        raise ValueError(f'{like} has {len(points)} vertices, the net {len(atoms)} points')
    mark, text = original_text(like)
    spans = [m.span(1) for m in _JSON_TOKEN.finditer(text) if m[1]]
    assert len(spans) == next(places), 'JSON numbers miscounted'
    edits, layout = {}, True
    for attributes, x in zip(points.values(), atoms.positions, strict=True):
        for axis, value in zip('xyz', map(float, x), strict=True):
            old = attributes.get(axis)
            if isinstance(old, (_PlacedInt, _PlacedFloat)):
                start, stop = spans[old.place]
                edits[start] = (stop, number_text(text[start:stop], value))
            elif value != defaults.get(axis):
                layout = False
            attributes[axis] = value
    changed = _update_forces(like, data, atoms.calc.springs, q, loads)
    changed = _update_supports(like, data, fixed_atoms(atoms)) or changed
    # q is Q q: a Q other than the file's changes what its q mean (an a
    # other than its own is stored where the document is written anew)
    parameters = _parameters(atoms)
    changed = changed or parameters.get('Q', 1.0) != _stored_parameters(like, data).get(
        'Q', 1.0)
    if result is not None:
        _set_results(like, data, result)
    if changed or result is not None or not layout:
        _set_parameters(data, parameters)
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
            added = data.setdefault('edgedata', {})[f'({keys[i]}, {keys[j]})'] = {}
            edges[(i, j)] = [added]
        for attributes in edges[(i, j)]:   # each time the file lists it
            attributes['q'] = float(q[s])
        changed = True
    return changed


def _update_supports(path, data, fixed) -> bool:
    """Mark the points ``fixed`` (a boolean mask) of COMPAS ``data`` (read
    from ``path``) ``is_anchor`` true, and the others false where the file
    says they are anchors (``is_anchor`` or ``is_fixed``); whether anything
    was set."""
    points, defaults = _compas_points(path, data)
    changed = False
    for attributes, held in zip(points.values(), fixed.tolist(), strict=True):
        said = any(attributes.get(name, defaults.get(name)) for name in ANCHOR_ATTRIBUTES)
        if said != held:
            attributes['is_anchor'] = held
            if not held:
                attributes['is_fixed'] = False
            changed = True
    return changed


def _set_results(path, data, result) -> None:
    """Edge attributes ``q``, ``force``, ``length`` of every member of
    ``result`` (a FormResult) and vertex attributes ``rx``, ``ry``, ``rz``
    of every support, in COMPAS ``data`` (of ``path``, or None for a graph
    written anew); a member that is no edge of the data (from an edge list)
    is left out."""
    points, _ = _compas_points(path, data)
    keys = list(points)
    edges = _edge_attributes(data, {str(k): n for n, k in enumerate(keys)})
    mesh = 'face' in data
    for (i, j), density, force, length in zip(
            result.edges.tolist(), result.force_densities.tolist(), result.forces.tolist(),
            result.lengths.tolist(), strict=True):
        pair = (min(i, j), max(i, j))
        if pair not in edges:
            if not mesh:
                continue
            edges[pair] = [data.setdefault('edgedata', {}).setdefault(
                f'({keys[pair[0]]}, {keys[pair[1]]})', {})]
        for attributes in edges[pair]:   # each time the file lists it
            attributes.update(q=density, force=force, length=length)
    for n, reaction in zip(result.supports.tolist(), result.reactions.tolist(),
                           strict=True):
        points[keys[n]].update(zip(REACTION_ATTRIBUTES, reaction, strict=True))


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
    said = atoms.calc.potential.q is not None or atoms.calc.potential.Q != 1
    for (i, j), qs in zip(atoms.calc.springs, q, strict=True):
        edge[str(i)][str(j)] = {'q': float(qs)} if said else {}
    data = {'attributes': {}, 'default_node_attributes': {'x': 0.0, 'y': 0.0, 'z': 0.0},
            'default_edge_attributes': {}, 'node': node, 'edge': edge,
            'max_node': len(atoms) - 1}
    return {'dtype': 'compas.datastructures/Graph', 'data': data,
            'guid': str(uuid.uuid4())}
