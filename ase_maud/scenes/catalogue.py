"""The scenes by name (:data:`SCENES`), the suites the benchmarks run, and
:func:`build`.
"""

from __future__ import annotations

import inspect

from ase import Atoms

from ase_maud.checks import as_whole
from ase_maud.scenes.builders import (
    all_pairs,
    all_pairs2d,
    cage,
    chain,
    dimer,
    disc,
    hanging_net,
    hub_net,
    molecule,
    neighbour_graph,
    net2d,
    net3d,
    random_graph,
    ring,
    tree,
    weighted_net,
    wheel,
)

SCENES = {f.__name__: f for f in (dimer, ring, chain, net2d, net3d,
                                  hanging_net, weighted_net, random_graph, all_pairs,
                                  all_pairs2d, tree, wheel, molecule, cage,
                                  hub_net, disc, neighbour_graph)}


#: Small scenes (under 60 points each) for the optimiser tests and benchmark.
SUITE = [('dimer', 2), ('ring', 16), ('chain', 20), ('net2d', 6),
         ('net3d', 5), ('hanging_net', 6), ('random_graph', 24),
         ('all_pairs', 8), ('all_pairs2d', 8), ('tree', 12), ('wheel', 8),
         ('molecule', 'C6H6'), ('cage', 8)]


#: Scenes whose slow modes move many points together (bending chains and
#: trees, breathing rings, a wheel's buckling rim, a net sagging as a whole,
#: a cluster's shells): 40 to 2500 points, for ``ase-maud bench --suite
#: collective``.
COLLECTIVE = [('chain', 100), ('ring', 100), ('ring', 1000), ('tree', 60),
              ('tree', 200), ('wheel', 100), ('hanging_net', 20),
              ('hanging_net', 50), ('weighted_net', 20), ('random_graph', 200),
              ('random_graph', 2000),
              ('all_pairs', 40)]


#: The scenes a form finder relaxes, 2000 to 10**4 points: nets with fixed
#: boundaries (square, polar with a hub, a triangulated membrane), a tree,
#: a random graph and a free neighbour graph, for ``ase-maud bench --suite
#: large``.
LARGE = [('hanging_net', 50), ('hanging_net', 100), ('hub_net', 48), ('disc', 3000),
         ('tree', 2000), ('random_graph', 2000), ('neighbour_graph', 2000)]


#: The named suites of ``ase-maud bench --suite``.
SUITES = {'small': SUITE, 'collective': COLLECTIVE, 'large': LARGE}


def scene_sizes(names: list[str] | None, sizes: list | None,
                suite: list[tuple[str, object]]) -> list[tuple[str, object]]:
    """(scene, size) pairs: ``suite``'s by default, ``names`` x ``sizes`` if
    both are given; a scene without a size takes its sizes in ``suite``, or
    its builder's default."""
    names = names or list(dict.fromkeys(name for name, _ in suite))
    if sizes:
        return [(name, size) for name in names for size in sizes]
    default = {name: inspect.signature(builder).parameters['size'].default
               for name, builder in SCENES.items()}
    return [(name, size) for name in names
            for size in [s for m, s in suite if m == name] or [default[name]]]


def build(name: str, size: int | str | None = None, seed: int = 0, **kwargs: float) -> Atoms:
    """Build scene ``name`` (a key of :data:`SCENES`); ``size=None`` takes
    the builder's default. Other keywords (``a``, ``Q``) go to the builder.

    Parameters
    ----------
    name : str
        A scene of :data:`SCENES`: ``'dimer'``, ``'ring'``, ``'chain'``,
        ``'net2d'``, ``'net3d'``, ``'hanging_net'``, ``'weighted_net'``,
        ``'random_graph'``, ``'all_pairs'``, ``'all_pairs2d'``, ``'tree'``,
        ``'wheel'``, ``'molecule'``, ``'cage'``, ``'hub_net'``, ``'disc'``,
        ``'neighbour_graph'``.
    size : int, str or None, default None
        The builder's size (points, or points along a side for the nets;
        a molecule's name for ``'molecule'``); None: its default.
    seed : int, default 0
        The seed of the start's random displacements (whole number >= 0).
    **kwargs : float
        ``a`` and ``Q``, the potential's length and spring constant (default
        1 each).

    Returns
    -------
    Atoms
        The start, with a :class:`~ase_maud.MaudCalculator` (springs, ``a``,
        ``Q``, ``dim``) and its fixed points as ``FixAtoms``; positions in
        the unit of ``a``. Planar scenes hold their z
        (:func:`~ase_maud.scenes.builders.keep_on_plane`).

    Raises
    ------
    ValueError
        An unknown scene (the known ones listed), a seed that is not a whole
        number >= 0, a keyword other than ``a`` and ``Q``, or a size the
        builder refuses (``ring needs an integer size >= 3, got 'x'``).
    """
    if not (isinstance(name, str) and name in SCENES):
        raise ValueError(f'unknown scene {name!r}; known: {", ".join(SCENES)}')
    whole_seed = as_whole(seed)
    if whole_seed is None or whole_seed < 0:
        raise ValueError(f'seed must be a whole number >= 0, got {seed!r}')
    seed = whole_seed
    if set(kwargs) - {'a', 'Q'}:
        raise ValueError(f'build takes the keywords a and Q, got '
                         f'{sorted(set(kwargs) - {"a", "Q"})}')
    if size is not None:
        kwargs['size'] = size
    return SCENES[name](seed=seed, **kwargs)
