"""The Maud optimizer: :class:`~ase_maud.optimize.maud.Maud`, ASE's adapter of
one step ``dr = gamma K^-1 f``. A step is a local model (the stiffness ``K``,
:mod:`~ase_maud.optimize.models`), a direction
(:mod:`~ase_maud.optimize.directions`) and a length
(:mod:`~ase_maud.optimize.step_length`), composed by a strategy
(:mod:`~ase_maud.optimize.strategy`, its rules in
:mod:`~ase_maud.optimize.step_rules` and its state in
:mod:`~ase_maud.optimize.state`) and watched by the run's monitor
(:mod:`~ase_maud.optimize.monitor`). What a run is made of is decided once
(:mod:`~ase_maud.optimize.run_setup`); a run nobody watches goes on arrays
(:mod:`~ase_maud.optimize.array_loop`); the restart file and the resume are
:mod:`~ase_maud.optimize.restart_file` and :mod:`~ase_maud.optimize.resume`.
"""
