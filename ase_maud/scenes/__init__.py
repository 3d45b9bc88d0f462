"""Seeded scenes, built by name: rings, chains, nets hanging or weighted,
cable nets with a hub, discs, neighbour graphs, random graphs, all-pairs
clusters, trees, molecules' bond graphs, cages (:mod:`~ase_maud.scenes.builders`);
the catalogue and the suites the benchmarks run (:mod:`~ase_maud.scenes.catalogue`,
:func:`build`); the hard inputs of the docs (:mod:`~ase_maud.scenes.hard_cases`); and
the starts of saddle searches (:mod:`~ase_maud.scenes.saddle_scenes`).
"""

from ase_maud.old_paths import old_names
from ase_maud.physics.dofs import keep_on_plane
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
from ase_maud.scenes.catalogue import COLLECTIVE, LARGE, SCENES, SUITE, SUITES, build, scene_sizes
from ase_maud.scenes.saddle_scenes import SADDLE_SCENES, chords, corners, rim, tube

__all__ = ['SCENES', 'SUITE', 'SUITES', 'COLLECTIVE', 'LARGE', 'build', 'scene_sizes',
           'keep_on_plane', 'dimer', 'ring', 'chain', 'net2d', 'net3d', 'hanging_net',
           'weighted_net', 'random_graph', 'all_pairs', 'all_pairs2d', 'tree', 'wheel',
           'molecule', 'cage', 'hub_net', 'disc', 'neighbour_graph', 'SADDLE_SCENES', 'chords',
           'corners', 'rim', 'tube']
#: The names of ase_maud 0.1's ``ase_maud.scenes`` module, handed on with a warning.
__getattr__ = old_names('scenes')
