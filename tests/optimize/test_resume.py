"""A relaxation killed with SIGKILL at seeded random steps and resumed from
its files ends where the uninterrupted run ends ("kill -9 loses no data").

The run (``hanging_net(8)``, 42 steps) goes in a subprocess with a restart
file and a trajectory. After each step's frame it reports the step on a pipe
and waits for the parent's word to go on, so the parent kills it at a step
it chose, whatever the machine's load: at that point (between the frame and
the restart file), or just after its word (somewhere in the next step). The
parent checks that the trajectory reads back with only complete, finite
frames, and resumes with ``Maud.resume`` or by hand (the last frame, the
restart file and the trajectory appended to: docs/hard_cases.md). Threads
are pinned to one everywhere, so the resumed run repeats the uninterrupted
one's steps exactly.
"""

import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from ase.io import read

from ase_maud import Maud
from ase_maud.files.trajectory import last_frame
from ase_maud.scenes.catalogue import build

SCENE = ('hanging_net', 8)
SEED = 3
FMAX = 1e-9
PINNED = {name: '1' for name in ('NUMBA_NUM_THREADS', 'OMP_NUM_THREADS',
                                 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')}

CHILD = f"""
from ase_maud import Maud
from ase_maud.files.trajectory import last_frame
from ase_maud.scenes import build
Maud(build({SCENE[0]!r}, {SCENE[1]}, seed={SEED}), logfile=None).run(steps=2)  # warm
import sys
atoms = build({SCENE[0]!r}, {SCENE[1]}, seed={SEED})
with Maud(atoms, restart='maud.json', trajectory='maud.traj', logfile=None) as opt:
    def report():   # after the frame, before the restart file
        print(opt.nsteps, flush=True)
        sys.stdin.readline()
    opt.attach(report)
    opt.run(fmax={FMAX})
"""


def uninterrupted():
    """The run without files, and its number of steps."""
    atoms = build(*SCENE, seed=SEED)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=FMAX)
    return atoms, opt.nsteps


def killed_run(directory, step, in_next):
    """Start the run in ``directory`` and SIGKILL it once it reports
    ``step``: there, or (``in_next``) just after telling it to go on, in the
    next step. Whether it was killed (not ended on its own)."""
    env = {**os.environ, **PINNED}
    child = subprocess.Popen([sys.executable, '-c', CHILD], cwd=directory, env=env,
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        for line in child.stdout:
            if int(line) == step:
                if in_next:
                    child.stdin.write('\n')
                    child.stdin.flush()
                child.send_signal(signal.SIGKILL)
                break
            child.stdin.write('\n')
            child.stdin.flush()
    finally:
        child.wait()
        child.stdin.close()
        child.stdout.close()
    return child.returncode == -signal.SIGKILL


def test_killed_runs_resume_to_the_same_minimum(tmp_path, monkeypatch):
    for name, value in PINNED.items():
        monkeypatch.setenv(name, value)
    reference, steps = uninterrupted()
    energy = reference.get_potential_energy()
    a = reference.calc.parameters['a']
    at = np.sort(np.random.default_rng(12).choice(steps - 1, 5, replace=False))
    for k, step in enumerate(at):
        directory = tmp_path / f'kill{k}'
        directory.mkdir()
        assert killed_run(directory, int(step), in_next=k >= 2), f'step {step}'

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
