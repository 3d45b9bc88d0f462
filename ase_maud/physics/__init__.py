"""The physics of a scene, with no solver in it: the pair law (repulsion
``a^3 Q / L`` and zero-length springs ``Q L^2 / 2``, their forces, nodal
blocks and Hessians: :mod:`~ase_maud.physics.pair_law`), what a spring list
may hold (:mod:`~ase_maud.physics.spring_list`), the spring graph and the
supports (:mod:`~ase_maud.physics.topology`), the degrees of freedom the
constraints leave (:mod:`~ase_maud.physics.dofs`) and nearest-neighbour
distances (:mod:`~ase_maud.physics.neighbours`).
"""

from ase_maud.old_paths import old_names

#: The names of ase_maud 0.1's ``ase_maud.physics`` module, handed on with a warning.
__getattr__ = old_names('physics')
