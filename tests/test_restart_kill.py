"""A relaxation killed with SIGKILL at random moments and resumed from its
files ends where the uninterrupted run ends ("kill -9 loses no data").

The run (``hanging_net(8)``, 42 steps, about 1 s) goes in a subprocess with
a restart file and a trajectory; the parent kills it at seeded random moments,
checks that the trajectory reads back with only complete, finite frames, and
resumes with ``Maud.resume`` or by hand (the last frame, the restart file and
the trajectory appended to: docs/hard_cases.md). Threads are pinned to one everywhere, so the
resumed run repeats the uninterrupted one's steps exactly.
"""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from ase.io import read

from ase_maud import Maud
from ase_maud.scenes import build
from ase_maud.trajectory import last_frame

SCENE = ('hanging_net', 8)
SEED = 3
FMAX = 1e-9
PINNED = {name: '1' for name in ('NUMBA_NUM_THREADS', 'OMP_NUM_THREADS',
                                 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')}

CHILD = f"""
from ase_maud import Maud
from ase_maud.trajectory import last_frame
from ase_maud.scenes import build
Maud(build({SCENE[0]!r}, {SCENE[1]}, seed={SEED}), logfile=None).run(steps=2)  # warm
atoms = build({SCENE[0]!r}, {SCENE[1]}, seed={SEED})
with Maud(atoms, restart='maud.json', trajectory='maud.traj', logfile=None) as opt:
    print('ready', flush=True)
    opt.run(fmax={FMAX})
"""


def uninterrupted():
    """The run without files, and its wall time after a warm-up (the
    kernels loaded or compiled)."""
    Maud(build(*SCENE, seed=SEED), logfile=None).run(steps=2)
    atoms = build(*SCENE, seed=SEED)
    start = time.perf_counter()
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=FMAX)
    return atoms, opt.nsteps, time.perf_counter() - start


def killed_run(directory, delay):
    """Start the run in ``directory``, SIGKILL it ``delay`` s after it starts
    stepping; whether it was still running when killed."""
    env = {**os.environ, **PINNED}
    child = subprocess.Popen([sys.executable, '-c', CHILD], cwd=directory, env=env,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == 'ready'
        time.sleep(delay)
        running = child.poll() is None
        child.send_signal(signal.SIGKILL)
    finally:
        child.wait()
        child.stdout.close()
    return running


def test_killed_runs_resume_to_the_same_minimum(tmp_path, monkeypatch):
    for name, value in PINNED.items():
        monkeypatch.setenv(name, value)
    reference, steps, seconds = uninterrupted()
    energy = reference.get_potential_energy()
    a = reference.calc.parameters['a']
    delays = np.random.default_rng(12).uniform(0.0, 1.2 * seconds, 5)
    kills = 0
    for k, delay in enumerate(sorted(delays)):
        directory = tmp_path / f'kill{k}'
        directory.mkdir()
        kills += killed_run(directory, delay)
        traj = directory / 'maud.traj'
        if traj.exists() and traj.stat().st_size:
            frames = read(traj, ':')   # every frame counted is complete
            assert all(np.isfinite(f.positions).all() and np.isfinite(f.get_forces()).all()
                       for f in frames)
        monkeypatch.chdir(directory)
        atoms = build(*SCENE, seed=SEED)
        if k % 2:   # the recipe by hand: the last frame, the files appended to
            frame = last_frame('maud.traj')
            if frame is not None:
                atoms.positions = frame.positions
            opt = Maud(atoms, restart='maud.json', trajectory='maud.traj',
                       append_trajectory=True, logfile=None)
        else:
            opt = Maud.resume(atoms, 'maud.json', 'maud.traj', logfile=None)
        with opt:
            assert opt.run(fmax=FMAX)
        assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-8, abs=0)
        assert np.abs(atoms.positions - reference.positions).max() < 1e-7 * a
        frames = read(traj, ':')
        assert np.array_equal(frames[-1].positions, atoms.positions)
        # One frame per step, and at most one written twice (a kill between
        # the frame and the restart file that follows it).
        assert steps + 1 <= len(frames) <= steps + 2
    assert kills >= 3, f'only {kills} of {len(delays)} runs were killed while running'
