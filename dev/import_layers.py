"""The import graph of ase_maud: floors, cycles and module sizes.

A module's floor is 1 plus the highest floor among the ase_maud modules it
imports (at module level; imports inside functions and under
``TYPE_CHECKING`` are listed apart); the longest chain of modules importing
each other is the highest floor. The same is done with each subpackage (and
each module of the top level) as one node. Package faces (``__init__.py``
files that only hand names on) are left out of the module graph, as a reader
of the code passes over them::

    python dev/import_layers.py            # floors, the longest chain, the largest modules
    python dev/import_layers.py --json     # the same as JSON
"""

from __future__ import annotations

import argparse
import ast
import json
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = 'ase_maud'


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def imports(path: Path, modules: set[str]) -> tuple[set[str], set[str]]:
    """(module-level, inside functions) ase_maud modules that ``path``
    imports; imports for type checkers only are left out."""
    tree = ast.parse(path.read_text())
    here = module_name(path)
    package = here if path.name == '__init__.py' else here.rpartition('.')[0]
    top, deferred = set(), set()
    deferred_nodes, typing_nodes = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            deferred_nodes.update(id(n) for n in ast.walk(node) if n is not node)
        elif isinstance(node, ast.If) and 'TYPE_CHECKING' in ast.unparse(node.test):
            typing_nodes.update(id(n) for n in ast.walk(node) if n is not node)
    for node in ast.walk(tree):
        found = set()
        if isinstance(node, ast.Import):
            found = {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                anchor = package.split('.')[:len(package.split('.')) - node.level + 1]
                base = '.'.join(anchor + ([node.module] if node.module else []))
            found = {f'{base}.{alias.name}' if f'{base}.{alias.name}' in modules else base
                     for alias in node.names}
        found = {m for m in found if m in modules and m != here}
        if id(node) not in typing_nodes:
            (deferred if id(node) in deferred_nodes else top).update(found)
    return top, deferred


def is_face(path: Path) -> bool:
    """An ``__init__.py`` that defines no function or class of its own."""
    tree = ast.parse(path.read_text())
    return path.name == '__init__.py' and not any(
        isinstance(n, (ast.FunctionDef, ast.ClassDef)) for n in tree.body)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args()
    paths = {module_name(p): p for p in sorted((ROOT / PACKAGE).rglob('*.py'))}
    modules = set(paths)
    faces = {m for m, p in paths.items() if is_face(p)}
    graph, deferred = {}, {}
    for m, p in paths.items():
        top, later = imports(p, modules)
        graph[m], deferred[m] = top - faces, later

    @cache
    def floor(m: str, stack: tuple = ()) -> int:
        if m in stack:
            raise SystemExit(f'import cycle: {" -> ".join(stack + (m,))}')
        return 1 + max((floor(d, stack + (m,)) for d in graph[m]), default=0)

    def chain(m: str) -> list[str]:
        below = max(graph[m], key=floor, default=None)
        return [m] + (chain(below) if below else [])

    def room(m: str) -> str:
        parts = m.split('.')
        return '.'.join(parts[:2]) if len(parts) > 1 else m

    rooms = {room(m) for m in modules if m not in faces or m.count('.') == 1}
    room_graph = {r: set() for r in rooms}
    for m, deps in graph.items():
        for d in deps | deferred[m]:
            if room(d) != room(m) and room(m) in room_graph:
                room_graph[room(m)].add(room(d))

    @cache
    def room_floor(r: str, stack: tuple = ()) -> int:
        if r in stack:
            raise SystemExit(f'subpackage cycle: {" -> ".join(stack + (r,))}')
        return 1 + max((room_floor(d, stack + (r,)) for d in room_graph[r]), default=0)

    live = [m for m in modules if m not in faces]
    top = max(live, key=floor)
    sizes = sorted(((len(paths[m].read_text().splitlines()), m) for m in modules), reverse=True)
    result = {
        'modules': len(modules), 'faces': len(faces),
        'module floors': floor(top), 'longest chain': chain(top),
        'subpackage floors': max(room_floor(r) for r in rooms),
        'subpackages by floor': {r: room_floor(r) for r in sorted(rooms, key=room_floor)},
        'largest modules': [[n, m] for n, m in sizes[:8]],
        'modules over 500 lines': [m for n, m in sizes if n > 500],
        'deferred imports': {m: sorted(d) for m, d in deferred.items() if d},
    }
    if args.json:
        print(json.dumps(result, indent=1))
        return
    for key, value in result.items():
        if key == 'deferred imports':
            print(f'{key}: {sum(map(len, value.values()))} in {len(value)} modules')
        elif isinstance(value, dict):
            print(f'{key}:')
            for k, v in value.items():
                print(f'  {v:3d}  {k}')
        else:
            print(f'{key}: {value}')


if __name__ == '__main__':
    main()
