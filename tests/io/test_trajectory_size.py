"""A run's trajectory stores the MaudCalculator's parameters with its first
frame only: within 5 % of ASE's own for the same frames, and every frame
read back whole (springs, a, q, loads) by read_net."""

import numpy as np
import pytest
from ase.calculators.singlepoint import SinglePointCalculator
from ase.io.trajectory import Trajectory

from ase_maud.cli.command import main
from ase_maud.io.nets import read_frames, read_net


@pytest.mark.parametrize('seed', [0, 1])
def test_run_trajectory_is_within_5_percent_of_ases_and_reads_back(tmp_path, seed):
    rng = np.random.default_rng(seed)
    ours = tmp_path / 'run.traj'
    main(['relax', '--scene', 'hanging_net', '--size', '12', '--seed', str(seed),
          '--steps', '8', '--fmax', '1e-12', '--quiet', '--traj', str(ours)])
    theirs = tmp_path / 'ase.traj'
    with Trajectory(ours) as frames, Trajectory(theirs, 'w') as out:
        count = len(frames)
        plain = frames[0].copy()
        for frame in frames:
            plain.positions = frame.positions
            plain.calc = SinglePointCalculator(plain, energy=frame.get_potential_energy(),
                                               forces=frame.get_forces(apply_constraint=False))
            out.write(plain)
    assert count >= 3
    assert ours.stat().st_size <= 1.05 * theirs.stat().st_size
    first, last = read_net(ours, index=0), read_net(ours, index=int(rng.integers(1, count)))
    for key in ('springs', 'a', 'Q', 'dim', 'loads'):
        np.testing.assert_array_equal(np.asarray(last.calc.parameters[key]),
                                      np.asarray(first.calc.parameters[key]))
    every = read_frames(ours)
    assert len(every) == count
    assert all(np.array_equal(f.calc.springs, first.calc.springs) for f in every)
