"""One rule for every file a command touches (ase_maud.files.output_paths): an output
that names an input or another output is refused before any work, with the
input's bytes unchanged; a trajectory replaces the previous one only once it
holds a frame."""

import json
import os
import re

import numpy as np
import pytest
from ase.io import read

from ase_maud import Maud
from ase_maud.cli.command import main
from ase_maud.errors import FileInUseError
from ase_maud.files.output_paths import StagedTrajectory, check_distinct, check_own_json, same_file
from ase_maud.scenes.catalogue import build

from helpers import write_quad_net


def refused(capsys, argv, *kept):
    """Run ``ase-maud argv``: exit 2, one line on stderr naming a clash, and
    every file of ``kept`` byte for byte as before. Returns the line."""
    before = [path.read_bytes() for path in kept]
    assert main([str(a) for a in argv]) == 2
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and re.search(r'an output may not overwrite an input|'
                                                 r'each output needs its own', error), error
    assert [path.read_bytes() for path in kept] == before
    return error


@pytest.fixture(params=[0, 1])
def net(tmp_path, request):
    """A random quad net as net.obj, with fixed.txt, in a fresh folder."""
    path, *_ = write_quad_net(tmp_path, 'obj', n=4, seed=request.param)
    return path


@pytest.mark.parametrize('option', ['--traj', '--log', '--out'])
def test_an_output_over_the_net_file_is_refused(capsys, net, option):
    error = refused(capsys, ['relax', net, '--fix', 'boundary', option, net, '--quiet'], net)
    assert f"{option} '{net}' is the file NET_FILE '{net}'" in error


@pytest.mark.parametrize('option', ['--traj', '--log'])
def test_an_output_over_the_fix_or_edges_file_is_refused(capsys, tmp_path, option):
    path, *_ = write_quad_net(tmp_path, 'xyz', n=4, seed=2)
    edges, fixed = tmp_path / 'net.edges.txt', tmp_path / 'fixed.txt'
    for given in (['--edges', edges], []):   # the edge list given, or beside net.xyz
        error = refused(capsys, ['relax', path, *given, '--fix', fixed, option, edges,
                                 '--quiet'], path, edges, fixed)
        assert "--edges" in error
    error = refused(capsys, ['relax', path, '--fix', fixed, option, fixed, '--quiet'],
                    path, edges, fixed)
    assert f"is the file --fix '{fixed}'" in error


def test_the_edge_list_written_beside_out_may_not_be_the_input(capsys, tmp_path):
    path, *_ = write_quad_net(tmp_path, 'xyz', n=4, seed=3)
    refused(capsys, ['relax', path, '--fix', tmp_path / 'fixed.txt', '--out',
                     tmp_path / 'net.extxyz', '--traj', tmp_path / 'o.traj', '--quiet'],
            path, tmp_path / 'net.edges.txt')


def test_relax_of_maud_traj_keeps_it(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(['relax', '--scene', 'ring', '--size', '9', '--seed', '4', '--quiet']) == 0
    frames = len(read('maud.traj', ':'))
    error = refused(capsys, ['relax', 'maud.traj', '--quiet'], tmp_path / 'maud.traj')
    assert "--traj 'maud.traj' is the file NET_FILE 'maud.traj'" in error
    (tmp_path / 'sub').mkdir()
    refused(capsys, ['relax', './maud.traj', '--traj', 'sub/../maud.traj', '--quiet'],
            tmp_path / 'maud.traj')
    assert len(read('maud.traj', ':')) == frames > 1


def test_links_name_the_same_file(capsys, net):
    soft, hard = net.with_name('soft.traj'), net.with_name('hard.traj')
    soft.symlink_to(net.name)
    os.link(net, hard)
    for link in (soft, hard):
        assert same_file(link, net) and same_file(f'{net.parent}/./{link.name}', net)
        refused(capsys, ['relax', net, '--fix', 'boundary', '--traj', link, '--quiet'], net)
    assert not same_file(net, net.with_name('fixed.txt'))


@pytest.mark.parametrize('argv', [['--traj', 'r.obj', '--out', 'r.obj'],
                                  ['--out', 'maud.traj'],
                                  ['--log', 'maud.traj'],
                                  ['--out', 'r.xyz', '--log', 'r.edges.txt']])
def test_two_outputs_on_one_file_are_refused(capsys, tmp_path, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    mine = tmp_path / argv[-1]
    mine.write_text('kept\n')
    error = refused(capsys, ['relax', '--scene', 'ring', '--size', '6', *argv, '--quiet'],
                    mine)
    assert 'each output needs its own' in error


def test_show_may_not_draw_over_its_input(capsys, net):
    picture = net.with_name('net.png')
    picture.symlink_to(net)
    refused(capsys, ['show', net, '--fix', 'boundary'], net)


@pytest.mark.parametrize('files', [dict(restart='m.json', logfile='m.json'),
                                   dict(restart='m.json', trajectory='./m.json'),
                                   dict(logfile='m.traj', trajectory='m.traj'),
                                   dict(restart='m.json', logfile='m.json.arrays')])
def test_maud_refuses_one_file_for_two_outputs(tmp_path, monkeypatch, files):
    monkeypatch.chdir(tmp_path)
    for name in set(files.values()):
        (tmp_path / name).write_text('mine\n')
    with pytest.raises(ValueError, match='are one file: each output needs its own'):
        Maud(build('ring', 6), **files)
    assert all((tmp_path / name).read_text() == 'mine\n' for name in files.values())


def test_a_run_refused_before_its_first_step_keeps_the_previous_trajectory(
        capsys, tmp_path):
    traj = tmp_path / 'o.traj'
    assert main(['relax', '--scene', 'ring', '--size', '7', '--traj', str(traj),
                 '--quiet']) == 0
    before = traj.read_bytes()
    path, *_ = write_quad_net(tmp_path, 'obj', n=4, seed=5)   # no point fixed: drifts
    assert main(['relax', str(path), '--load', '0', '0', '-1', '--traj', str(traj),
                 '--quiet']) == 2
    assert 'before the first step' in capsys.readouterr().err
    assert traj.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['fixed.txt', 'net.obj', 'o.traj']


def test_a_staged_trajectory_replaces_its_file_at_the_first_frame(tmp_path):
    traj = tmp_path / 'run.traj'
    traj.write_bytes(b'previous')
    atoms = build('ring', 5, seed=6)
    with StagedTrajectory(traj) as staged:
        assert traj.read_bytes() == b'previous'
        staged.keep()   # no frame yet: nothing to keep
        assert not staged.kept and traj.read_bytes() == b'previous'
        staged.trajectory.write(atoms)
        staged.keep()
        staged.trajectory.write(atoms)   # written on, in its place
    assert staged.kept and len(read(traj, ':')) == 2
    assert list(tmp_path.iterdir()) == [traj]
    with StagedTrajectory(traj):
        pass
    assert len(read(traj, ':')) == 2 and list(tmp_path.iterdir()) == [traj]


def test_the_graph_json_of_saddles_does_not_replace_a_users_file(capsys, tmp_path):
    net = tmp_path / 'net.traj'
    atoms = build('ring', 6, seed=7)
    atoms.get_potential_energy()
    atoms.write(net)
    compas = tmp_path / 'graph.json'
    compas.write_text(json.dumps({'dtype': 'compas.datastructures/Graph', 'data': {}}))
    before = compas.read_bytes()
    assert main(['saddles', str(net), '--out', str(tmp_path / 'graph.png')]) == 2
    error = capsys.readouterr().err
    assert 'graph.json' in error and 'was not written by ase-maud saddles' in error
    assert compas.read_bytes() == before
    ours = dict.fromkeys(('minima', 'saddles', 'joins', 'barriers', 'failed'), [])
    compas.write_text(json.dumps(ours))
    check_own_json('--out', compas, tuple(ours), 'ase-maud saddles')   # replaced


def test_check_distinct_names_both_arguments(tmp_path):
    rng = np.random.default_rng(8)
    name = f'{rng.integers(10**6)}.obj'
    with pytest.raises(ValueError, match=rf"^--b '{tmp_path}/x/../{name}' is the file "
                                         rf"A '{tmp_path}/{name}' is read from"):
        check_distinct([('A', tmp_path / name)], [('--b', f'{tmp_path}/x/../{name}')])
    check_distinct([('A', tmp_path / name), ('B', None)],
                   [('--b', tmp_path / 'other.obj'), ('--c', None)])


@pytest.mark.parametrize('at', [0, 3])
def test_ctrl_c_ends_relax_in_one_line_with_its_files_whole(capsys, tmp_path, monkeypatch,
                                                           at):
    traj = tmp_path / 'o.traj'
    traj.write_bytes(b'previous')
    step = Maud.step

    def interrupted(self, *args, **kwargs):
        if self.nsteps == at:
            raise KeyboardInterrupt
        return step(self, *args, **kwargs)

    monkeypatch.setattr(Maud, 'step', interrupted)
    assert main(['relax', '--scene', 'ring', '--size', '8', '--seed', str(at), '--traj',
                 str(traj), '--out', str(tmp_path / 'r.obj'), '--quiet']) == 130
    error = capsys.readouterr().err
    assert error == (f'ase-maud: interrupted at step {at}; trajectory {traj} holds the '
                     'steps so far, --out not written\n')
    assert len(read(traj, ':')) == at + 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ['o.traj']


@pytest.mark.parametrize('previous', [True, False])
def test_a_second_writer_of_a_staged_trajectory_is_refused(tmp_path, previous):
    traj = tmp_path / 'run.traj'
    if previous:
        traj.write_bytes(b'previous')
    atoms = build('ring', 5, seed=9)
    with StagedTrajectory(traj) as staged:
        if previous:   # the previous file is held until the first frame replaces it
            with pytest.raises(FileInUseError, match='in use by another run'):
                StagedTrajectory(traj)
        staged.trajectory.write(atoms)
        staged.keep()
        with pytest.raises(FileInUseError, match='in use by another run'):
            StagedTrajectory(traj)
    assert len(read(traj, ':')) == 1 and list(tmp_path.iterdir()) == [traj]
    with StagedTrajectory(traj):   # released
        pass
    assert len(read(traj, ':')) == 1


@pytest.mark.parametrize('seed', [3, 4])
def test_two_staged_trajectories_started_on_no_file_keep_the_first(tmp_path, seed):
    # Both start before either has a frame (no file to lock yet): the first
    # frame kept wins, the other run is refused at its first frame, its own
    # file removed (it had replaced the first run's trajectory without a word).
    traj = tmp_path / 'run.traj'
    first, second = build('ring', 5, seed=seed), build('ring', 6, seed=seed)
    with StagedTrajectory(traj) as a, StagedTrajectory(traj) as b:
        b.trajectory.write(second)
        b.keep()
        a.trajectory.write(first)
        with pytest.raises(FileInUseError, match='written by another run'):
            a.keep()
        b.trajectory.write(second)
    frames = read(traj, ':')
    assert [len(f) for f in frames] == [6, 6] and list(tmp_path.iterdir()) == [traj]


def test_ctrl_c_in_another_command_is_one_line(capsys, monkeypatch, net):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr('ase_maud.analysis.stationary.classify', interrupted)
    assert main(['classify', str(net), '--fix', 'boundary']) == 130
    assert capsys.readouterr().err == 'ase-maud: interrupted\n'
