"""A run's files against a cut and against a second writer: a trajectory cut
short is resumed from its last intact frame (the cut file kept), a damaged
header is refused by name, and a second run on the files of a running one is
refused before it touches them, in this process or another; a killed run
leaves no lock behind."""

import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
from ase.io import read
from ase.optimize import BFGS

from ase_maud import FileInUseError, Maud
from ase_maud.files.trajectory import intact, last_frame, repair
from ase_maud.scenes.catalogue import build

SCENE = ('hanging_net', 8)


def reference_energy(seed):
    """BFGS's minimum energy from the scene's start. To fmax 1e-5 it lies
    within 4e-13 relative of the minimum (seeds 0-4, against Maud to 1e-6;
    measured 2026-12-03), far inside the tests' 1e-9: 250-300 steps where
    fmax 1e-8 took 440-1570."""
    atoms = build(*SCENE, seed=seed)
    BFGS(atoms, logfile=None).run(fmax=1e-5, steps=3000)
    return atoms.get_potential_energy()


def stopped_run(directory, seed, steps):
    """A run of ``steps`` steps with a restart file and a trajectory."""
    restart, trajectory = directory / 'maud.json', directory / 'maud.traj'
    with Maud(build(*SCENE, seed=seed), logfile=None, restart=restart,
              trajectory=trajectory) as opt:
        opt.run(fmax=1e-9, steps=steps)
    return restart, trajectory


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_cut_trajectory_resumes_from_its_last_intact_frame(tmp_path, seed):
    rng = np.random.default_rng(seed)
    restart, trajectory = stopped_run(tmp_path, seed, steps=int(rng.integers(4, 8)))
    frames = read(trajectory, ':')
    data = trajectory.read_bytes()
    frame_bytes = len(data) // len(frames)
    cut = int(rng.integers(1, 2 * frame_bytes))       # into the last frame or two
    trajectory.write_bytes(data[:-cut])
    count, named = intact(trajectory)
    assert named == len(frames) and 0 < count < named
    last = last_frame(trajectory)
    np.testing.assert_array_equal(last.positions, frames[count - 1].positions)
    with pytest.warns(UserWarning, match=rf'frames? .*of {named} w.* damaged.* kept as'):
        opt = Maud.resume(build(*SCENE, seed=seed), restart=restart,
                          trajectory=trajectory, logfile=None)
    with opt:
        assert opt.run(fmax=1e-6)
        energy = opt.optimizable.atoms.get_potential_energy()
    assert energy == pytest.approx(reference_energy(seed), rel=1e-9)
    resumed = read(trajectory, ':')                     # every frame reads whole
    for k in range(count):
        np.testing.assert_array_equal(resumed[k].positions, frames[k].positions)
    assert (tmp_path / 'maud.traj.damaged').read_bytes() == data[:-cut]


def test_a_whole_trajectory_is_left_alone(tmp_path):
    _, trajectory = stopped_run(tmp_path, 4, steps=3)
    before = trajectory.read_bytes()
    assert repair(trajectory) is None
    assert trajectory.read_bytes() == before


@pytest.mark.parametrize('seed', [0, 1])
def test_a_trajectory_cut_into_its_header_is_refused_by_name(tmp_path, seed):
    restart, trajectory = stopped_run(tmp_path, seed, steps=3)
    data = trajectory.read_bytes()
    trajectory.write_bytes(data[:int(np.random.default_rng(seed).integers(1, 24))])
    with pytest.raises(ValueError, match=r"trajectory '.*maud.traj' cannot be read"):
        Maud.resume(build(*SCENE, seed=seed), restart=restart, trajectory=trajectory,
                    logfile=None)


@pytest.mark.parametrize('which', ['restart', 'trajectory'])
def test_a_second_run_on_the_files_of_a_running_one_is_refused(tmp_path, which):
    files = {'restart': tmp_path / 'maud.json', 'trajectory': tmp_path / 'maud.traj'}
    first = Maud(build(*SCENE, seed=5), logfile=None, **files)
    running = first.irun(fmax=1e-9, steps=50)
    for _ in range(3):
        next(running)                                   # it holds its files now
    size = files[which].stat().st_size if which == 'trajectory' else None
    name = {'restart': "restart file '.*maud.json'", 'trajectory': "trajectory '.*maud.traj'"}
    with pytest.raises(FileInUseError, match=f'{name[which]} is in use'):
        Maud(build(*SCENE, seed=5), logfile=None, **{which: files[which]})
    if size is not None:
        assert files[which].stat().st_size == size       # not emptied
    for _ in running:                                   # the first run goes on, whole
        pass
    first.close()
    assert len(read(files['trajectory'], ':')) == first.nsteps + 1
    with Maud.resume(build(*SCENE, seed=5), logfile=None, **files) as opt:
        assert opt.run(fmax=1e-6)                       # free again once it stopped


CHILD = """
import sys, time
from ase_maud import Maud
from ase_maud.scenes import build
opt = Maud(build('hanging_net', 8, seed=6), restart='maud.json', trajectory='maud.traj',
           logfile=None)
opt.attach(lambda: (print('step', flush=True), time.sleep(0.2)))
opt.run(fmax=1e-12, steps=10**6)
"""


def test_a_run_in_another_process_holds_its_files_until_it_dies(tmp_path):
    env = {**os.environ, 'OMP_NUM_THREADS': '1', 'NUMBA_NUM_THREADS': '1'}
    child = subprocess.Popen([sys.executable, '-c', CHILD], cwd=tmp_path, env=env,
                             stdout=subprocess.PIPE, text=True)
    try:
        for _ in range(3):
            assert child.stdout.readline() == 'step\n'
        with pytest.raises(FileInUseError, match='in use by another run'):
            Maud.resume(build('hanging_net', 8, seed=6), restart=tmp_path / 'maud.json',
                        trajectory=tmp_path / 'maud.traj', logfile=None)
    finally:
        child.kill()
        child.wait()
    with warnings.catch_warnings():
        warnings.simplefilter('error')                  # the killed run left whole files
        opt = Maud.resume(build('hanging_net', 8, seed=6), restart=tmp_path / 'maud.json',
                          trajectory=tmp_path / 'maud.traj', logfile=None)
    with opt:
        assert opt.run(fmax=1e-6)
