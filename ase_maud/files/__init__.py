"""The files a run writes, kept safe: atomic replacement
(:mod:`~ase_maud.files.atomic_replace`), the lock on a run's files
(:mod:`~ase_maud.files.run_lock`), the rule that no output names an input or
another output (:mod:`~ase_maud.files.output_paths`) and trajectories repaired
to their last whole frame (:mod:`~ase_maud.files.trajectory`).
"""
