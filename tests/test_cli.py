"""The ase-maud command: help, relax, scene selection, thread pinning."""

import os
import subprocess
import sys

import numba
import numpy as np
import pytest
from ase.io import read

from ase_maud import cli
from ase_maud.cli import main
from ase_maud.scenes import SUITE, scene_sizes
from ase_maud.threads import THREAD_VARIABLES


def test_no_command_prints_help(capsys):
    assert main([]) == 0
    out = capsys.readouterr().out
    assert out.startswith('usage: ase-maud')
    assert all(command in out for command in ('relax', 'bench', 'backends'))


def test_bench_help_documents_options(capsys):
    with pytest.raises(SystemExit) as exit:
        main(['bench', '--help'])
    assert exit.value.code == 0
    out = capsys.readouterr().out
    for option in ('--scenes', '--sizes', '--seeds', '--optimizers',
                   '--threads', '--fmax', '--out', '--progress'):
        assert option in out


def test_threads_defaults():
    parser = cli.build_parser()
    assert parser.parse_args(['relax']).threads is None  # environment alone
    assert parser.parse_args(['bench']).threads == 1
    assert parser.parse_args(['backends', '--threads', '2']).threads == 2


def test_python_m_runs_the_command():
    done = subprocess.run([sys.executable, '-m', 'ase_maud'],
                          capture_output=True, text=True, check=True)
    assert done.stdout.startswith('usage: ase-maud')


@pytest.mark.parametrize('seed, method, fmax', [(0, 'tensor', 1e-4),
                                                (5, 'scalar', 1e-5)])
def test_relax_writes_a_converged_trajectory(tmp_path, capsys, seed, method,
                                             fmax):
    traj = tmp_path / 'net.traj'
    assert main(['relax', '--scene', 'net2d', '--size', '5', '--seed',
                 str(seed), '--method', method, '--fmax', str(fmax),
                 '--traj', str(traj)]) == 0
    frames = read(traj, ':')
    assert len(frames) > 2 and len(frames[0]) == 25
    last = frames[-1]
    assert np.sqrt((last.get_forces()**2).sum(axis=1).max()) < fmax
    assert not np.allclose(frames[0].positions, last.positions)
    log, summary = capsys.readouterr().out.rstrip().rsplit('\n', 1)
    assert 'Maud:' in log
    assert summary.startswith('converged: net2d 25 points')
    assert f'{last.get_potential_energy():.12g}' in summary


def test_relax_reports_failure(tmp_path, capsys):
    assert main(['relax', '--scene', 'chain', '--size', '12', '--steps', '2',
                 '--traj', str(tmp_path / 'c.traj')]) == 1
    assert 'NOT converged: chain 12 points, 2 steps' in capsys.readouterr().out


def test_scene_selection():
    assert scene_sizes(None, None, SUITE) == SUITE
    assert scene_sizes(['ring', 'dimer'], None, SUITE) == [('ring', 16),
                                                          ('dimer', 2)]
    assert scene_sizes(['ring', 'chain'], [5, 9], SUITE) == [
        ('ring', 5), ('ring', 9), ('chain', 5), ('chain', 9)]
    assert scene_sizes(['chain', 'molecule'], None, [('ring', 16)]) == [
        ('chain', 30), ('molecule', 'C6H6')]
    assert cli._size('12') == 12 and cli._size('CH4') == 'CH4'


@pytest.mark.parametrize('threads', [1, 2])
def test_pin_threads(monkeypatch, threads):
    restarts = []

    def execv(path, args):
        restarts.append(args)
        raise SystemExit

    monkeypatch.setattr(os, 'execv', execv)
    for variable in THREAD_VARIABLES:
        monkeypatch.delenv(variable, raising=False)
    before = numba.get_num_threads()
    try:
        with pytest.raises(SystemExit):   # numpy is loaded: start again
            cli.pin_threads(threads, restart=True)
        assert restarts == [[sys.executable, '-m', 'ase_maud',
                             *sys.argv[1:]]]
        assert all(os.environ[v] == str(threads) for v in THREAD_VARIABLES)
        cli.pin_threads(threads, restart=True)  # now in force: no restart
        assert len(restarts) == 1
        assert numba.get_num_threads() == min(
            threads, numba.config.NUMBA_NUM_THREADS)
        monkeypatch.delenv('OPENBLAS_NUM_THREADS')
        with pytest.warns(UserWarning, match='BLAS may use another count'):
            cli.pin_threads(threads, restart=False)
    finally:
        numba.set_num_threads(before)
