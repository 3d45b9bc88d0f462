"""The restart file (ase_maud.optimize.restart_file): replaced whole, its
positions winning and logged, refused for another scene or for rows that never
reached the disk, written on its schedule, its damaged values named; a run
without files starts afresh."""

import json
import os
import shutil

import numpy as np
import pytest
from ase.io import read

from ase_maud import Maud
from ase_maud.bench.hard_inputs import DAMAGES
from ase_maud.optimize.restart_file import RestartFile
from ase_maud.scenes.catalogue import build

# -- 3. the restart file -------------------------------------------------------------

def test_restart_file_is_replaced_whole(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    atoms = build('hanging_net', 5, seed=1)
    seen, replaced = [], []
    real_replace = os.replace

    def checked_replace(source, destination):
        """At the moment of the swap: the new state is whole, in the same
        folder, and names rows of the arrays file that are written already;
        the old file (if any) is whole too."""
        assert os.path.dirname(os.path.abspath(source)) == str(tmp_path)
        new = json.loads(open(source).read())
        shutil.copy(source, 'check.json')
        shutil.copy('maud.json.arrays', 'check.json.arrays')
        assert RestartFile('check.json').read()['step'] == new['step']
        os.remove('check.json')
        os.remove('check.json.arrays')
        if os.path.exists(destination):
            json.loads(open(destination).read())
        replaced.append(destination)
        real_replace(source, destination)

    monkeypatch.setattr('ase_maud.files.atomic_replace.os.replace', checked_replace)
    with Maud(atoms, logfile=None, restart='maud.json') as opt:
        opt.attach(lambda: seen.append(sorted(os.listdir('.'))))
        opt.run(fmax=1e-6, steps=5)
    assert len(replaced) == opt.nsteps                     # one swap per step
    # (the observers run before the file is written: from the second step on)
    assert all(names == ['maud.json', 'maud.json.arrays'] for names in seen[2:])
    saved = RestartFile(tmp_path / 'maud.json').read()
    assert saved['step'] == opt.nsteps
    assert np.array_equal(saved['x'], atoms.positions)


def test_restart_positions_win_and_are_logged(tmp_path):
    restart, log = tmp_path / 'maud.json', tmp_path / 'maud.log'
    straight = build('hanging_net', 5, seed=1)
    with Maud(straight, logfile=None) as opt:
        opt.run(fmax=1e-9)
    atoms = build('hanging_net', 5, seed=1)
    with Maud(atoms, logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=6)
    moved = build('hanging_net', 5, seed=1)   # the start, not step 6
    with Maud(moved, logfile=log, restart=restart) as opt:
        assert np.array_equal(moved.positions, atoms.positions)
        opt.run(fmax=1e-9)
    assert 'the atoms moved to the positions of step 6' in log.read_text()
    assert np.abs(moved.positions - straight.positions).max() < 1e-12


def test_restart_of_another_scene_is_refused(tmp_path):
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 5, seed=1), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-6, steps=2)
    with pytest.raises(ValueError, match=r'of another scene: points 25 in it, 36 in the '
                                         'atoms given'):
        Maud(build('hanging_net', 6, seed=1), logfile=None, restart=restart)
    restart.write_text('{"method": {}}')
    with pytest.raises(ValueError, match='not written by this version of Maud'):
        Maud(build('hanging_net', 5, seed=1), logfile=None, restart=restart)


def test_resume_without_files_starts_afresh(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    atoms = build('ring', 8, seed=1)
    start = atoms.positions.copy()
    with Maud.resume(atoms, logfile=None) as opt:
        assert np.array_equal(atoms.positions, start)
        assert opt.run(fmax=1e-6)
    assert len(read('maud.traj', ':')) == opt.nsteps + 1


def test_rows_that_never_reached_the_disk_are_refused(tmp_path):
    atoms = build('hanging_net', 12, seed=2)     # the springs model: L-BFGS pairs too
    restart = tmp_path / 'maud.json'
    with Maud(atoms, logfile=None, restart=restart, model='springs') as opt:
        opt.run(fmax=1e-9, steps=6)
    assert RestartFile(restart).read()['step'] == 6
    arrays = tmp_path / 'maud.json.arrays'
    data = bytearray(arrays.read_bytes())
    data[-8:] = bytes(range(1, 9))                # the last pair's last number
    arrays.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="rows .* of '.*maud.json.arrays' are not what it "
                                         'wrote'):
        Maud(build('hanging_net', 12, seed=2), logfile=None, restart=restart)


@pytest.mark.parametrize('sync_seconds,flushes', [(0.0, 'every step'), (1e9, 'none')])
@pytest.mark.parametrize('seed', [4, 9])
def test_restart_files_reach_the_disk_on_the_schedule(tmp_path, monkeypatch, seed,
                                                      sync_seconds, flushes):
    # both files flushed at each write when SYNC_SECONDS has passed; never
    # within it, not even at the first step
    from ase_maud.optimize import restart_file as restart_module
    monkeypatch.setattr(restart_module, 'SYNC_SECONDS', sync_seconds)
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, 'fsync', lambda fd: (synced.append(fd), real_fsync(fd)))
    steps = int(np.random.default_rng(seed).integers(3, 8))
    with Maud(build('hanging_net', 6, seed=seed), logfile=None,
              restart=tmp_path / 'maud.json', model='springs') as opt:
        opt.run(fmax=1e-12, steps=steps)
    assert opt.nsteps == steps
    writes = opt.nsteps if flushes == 'every step' else 0   # one write per step
    assert len(synced) == 2 * writes


@pytest.mark.parametrize('seed', [3, 8])
def test_files_of_another_scene_with_as_many_points_are_refused(tmp_path, seed):
    # a ring's run resumed onto a net of as many points:
    # other springs, then the same springs with another a, or other fixed points
    ring = build('ring', 25, seed=seed)
    restart, trajectory = tmp_path / 'maud.json', tmp_path / 'maud.traj'
    with Maud(ring, logfile=None, restart=restart, trajectory=trajectory) as opt:
        opt.run(fmax=1e-6, steps=3)
    net = build('hanging_net', 5, seed=seed)
    with pytest.raises(ValueError, match=r"restart file .* of another scene: fixed points "
                                         r'0 in it, \d+ in the atoms given'):
        Maud(net, logfile=None, restart=restart)
    with pytest.raises(ValueError, match=r"trajectory .* of another scene: fixed points"):
        Maud.resume(net, restart=restart, trajectory=trajectory, logfile=None)
    net.set_constraint()
    with pytest.raises(ValueError, match=r'of another scene: its springs are other ones '
                                         r'\(as many: 25\)|springs 25 in it'):
        Maud(net, logfile=None, restart=restart)
    wider = build('ring', 25, seed=seed)
    wider.calc.set(a=2.0)
    for resume in (lambda: Maud(wider, logfile=None, restart=restart),
                   lambda: Maud.resume(wider, restart=restart, trajectory=trajectory,
                                       logfile=None)):
        with pytest.raises(ValueError, match=r'of another scene: a 1\.0 in it, 2\.0 in the '
                                             'atoms given'):
            resume()
    same = build('ring', 25, seed=seed)
    with Maud.resume(same, restart=restart, trajectory=trajectory, logfile=None) as opt:
        assert opt.run(fmax=1e-6)


@pytest.mark.parametrize('seed', [0, 4])
def test_loads_and_force_densities_are_part_of_the_scene(tmp_path, seed):
    # a loaded net with force densities resumed from its files: the same
    # steps as the run never stopped; other loads or other q are refused
    def scene():
        atoms = build('weighted_net', 6, seed=seed)
        rng = np.random.default_rng(seed)
        atoms.calc.set(q=rng.uniform(0.5, 2.0, len(atoms.calc.springs)))
        return atoms

    straight = scene()   # with a restart file too: ASE's loop
    with Maud(straight, logfile=None, restart=tmp_path / 'straight.json') as opt:
        opt.run(fmax=1e-300, steps=12)
    restart, trajectory = tmp_path / 'maud.json', tmp_path / 'maud.traj'
    with Maud(scene(), logfile=None, restart=restart, trajectory=trajectory) as opt:
        opt.run(fmax=1e-300, steps=5)
    heavier = scene()
    heavier.calc.set(loads=2 * heavier.calc.parameters['loads'])
    softer = scene()
    softer.calc.set(q=0.5 * softer.calc.parameters['q'])
    for atoms, what in ((heavier, r'loads are other ones \(as many: 16\)'),
                        (softer, r'force densities are other ones \(as many: 60\)')):
        with pytest.raises(ValueError, match=f'of another scene: its {what}'):
            Maud(atoms, logfile=None, restart=restart)
        with pytest.raises(ValueError, match=f'of another scene: its {what}'):
            Maud.resume(atoms, restart=restart, trajectory=trajectory, logfile=None)
    resumed = scene()
    with Maud.resume(resumed, restart=restart, trajectory=trajectory, logfile=None) as opt:
        opt.run(fmax=1e-300, steps=7)
    np.testing.assert_array_equal(resumed.positions, straight.positions)


@pytest.mark.parametrize('damage', sorted(DAMAGES))
@pytest.mark.parametrize('seed', [0, 1])
def test_damaged_restart_values_are_named_and_leave_the_atoms(tmp_path, damage, seed):
    edit, match = DAMAGES[damage]
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 8, seed=seed), logfile=None, restart=restart,
              model='springs') as opt:
        opt.run(fmax=1e-9, steps=int(np.random.default_rng(seed).integers(3, 7)))
    document = json.loads(restart.read_text())
    edit(document)
    restart.write_text(json.dumps(document))
    atoms = build('hanging_net', 8, seed=seed)
    start = atoms.positions.copy()
    match = match if match.startswith(':') else ' is damaged: ' + match
    with pytest.raises(ValueError, match=r"restart file '.*maud.json'" + match):
        Maud(atoms, logfile=None, restart=restart)
    np.testing.assert_array_equal(atoms.positions, start)


@pytest.mark.parametrize('seed', [0, 1])
def test_non_finite_restart_rows_are_refused(tmp_path, seed):
    # NaN written into the positions with a matching CRC: refused all the same
    import zlib
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 8, seed=seed), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=3)
    document = json.loads(restart.read_text())
    rows, slot = document['rows'], document['slot']
    arrays = tmp_path / 'maud.json.arrays'
    table = np.fromfile(arrays).reshape(-1, rows)
    table[3 * slot, int(np.random.default_rng(seed).integers(rows))] = np.nan
    table.tofile(arrays)
    document['crc']['state'] = zlib.crc32(table[3 * slot:3 * slot + 3].tobytes())
    restart.write_text(json.dumps(document))
    atoms = build('hanging_net', 8, seed=seed)
    start = atoms.positions.copy()
    with pytest.raises(ValueError, match='hold non-finite numbers'):
        Maud(atoms, logfile=None, restart=restart)
    np.testing.assert_array_equal(atoms.positions, start)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_restart_file_missing_a_scene_key_is_refused(tmp_path, seed):
    restart = tmp_path / 'm.json'
    with Maud(build('hanging_net', 4, seed=seed), restart=restart, logfile=None) as opt:
        opt.run(fmax=1e-9, steps=3)
    document = json.loads(restart.read_text())
    keys = sorted(document['scene'])
    assert len(keys) >= 10   # points, fixed points, springs, a, Q, dim, ... with CRCs
    key = keys[np.random.default_rng(seed).integers(len(keys))]
    del document['scene'][key]
    restart.write_text(json.dumps(document))
    with pytest.raises(ValueError, match=f"is of another scene: its scene has no '{key}'"):
        Maud(build('hanging_net', 4, seed=seed), restart=restart, logfile=None)
    document['scene'] = {}
    restart.write_text(json.dumps(document))
    with pytest.raises(ValueError, match='its scene has no'):
        Maud(build('hanging_net', 4, seed=seed), restart=restart, logfile=None)
