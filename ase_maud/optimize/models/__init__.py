"""The stiffness models ``K`` of the Maud step, one module each: the
interface (:mod:`~ase_maud.optimize.models.base`), exact, springs, global,
nodal, secant and near-field models, the sparse solves they share, and the
registry that picks one by name or for a scene
(:mod:`~ase_maud.optimize.models.registry`).
"""
