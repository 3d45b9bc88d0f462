"""The ase-maud command: help, relax (a scene or a net file), show, classify,
scene selection, thread pinning."""

import os
import subprocess
import sys

import numba
import numpy as np
import pytest
from ase.io import read
from test_io import relaxed_in_python, rule_a, write_quad_net

from ase_maud import cli
from ase_maud.cli import main
from ase_maud.io import read_net, write_net
from ase_maud.scenes import SUITE, build, scene_sizes
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


# --- nets from files: relax, show, classify -----------------------------------

FILE_FORMATS = ('obj', 'mesh2.json', 'network1.json', 'xyz')


@pytest.mark.parametrize('kind', FILE_FORMATS)
def test_relax_a_net_file_matches_python(tmp_path, capsys, kind):
    """``ase-maud relax net.obj --fixed fixed.txt --fmax 1e-6 --traj out.traj``
    ends at the energy of the same net relaxed with Maud from Python, and
    writes the relaxed net in the format it came in."""
    path, positions, springs, fixed = write_quad_net(tmp_path, kind, seed=7)
    traj, out = tmp_path / 'out.traj', tmp_path / f'relaxed.{kind}'
    assert main(['relax', str(path), '--fixed', str(tmp_path / 'fixed.txt'),
                 '--fmax', '1e-6', '--traj', str(traj), '--out', str(out),
                 '--quiet']) == 0
    summary = capsys.readouterr().out
    assert summary.startswith(f'converged: net.{kind} 25 points') and 'Maud:' not in summary
    expected = relaxed_in_python(positions, springs, fixed)
    # the relaxed file stores no a: the start's is given again
    for relaxed in (read_net(traj), read_net(out, fixed=fixed, a=rule_a(positions, springs))):
        assert relaxed.get_potential_energy() == pytest.approx(expected, rel=1e-9)
        assert np.linalg.norm(relaxed.get_forces(), axis=1).max() < 1e-6


def test_relax_a_flat_net_in_its_plane(tmp_path, capsys):
    path, positions, springs, fixed = write_quad_net(tmp_path, 'obj', seed=2, flat=True)
    traj = tmp_path / 'flat.traj'
    assert main(['relax', str(path), '--fixed', str(tmp_path / 'fixed.txt'),
                 '--fmax', '1e-6', '--traj', str(traj), '--log', '-']) == 0
    assert 'Maud:' in capsys.readouterr().out   # ASE's log asked for on stdout
    relaxed = read_net(traj)
    assert relaxed.calc.dim == 2 and np.ptp(relaxed.positions[:, 2]) == 0
    assert relaxed.get_potential_energy() == pytest.approx(
        relaxed_in_python(positions, springs, fixed, dim=2), rel=1e-9)


def test_relax_progress_bar_and_log_file(tmp_path, capsys):
    path, *_ = write_quad_net(tmp_path, 'obj', n=4)
    log = tmp_path / 'relax.log'
    assert main(['relax', str(path), '--fmax', '1e-4', '--traj', str(tmp_path / 'o.traj'),
                 '--progress', '--log', str(log)]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith('converged: net.obj 16 points')   # only the summary
    assert 'step' in captured.err and 'fmax' in captured.err and 'energy' in captured.err
    assert 'Maud:' in log.read_text()


@pytest.mark.parametrize('option', ['--fixed', '--fix'])
def test_relax_net_options_need_a_file(capsys, option):
    with pytest.raises(SystemExit):
        main(['relax', option, 'fixed.txt'])
    assert '--fix and --dim need NET_FILE' in capsys.readouterr().err


def test_relax_a_malformed_file_names_the_line(tmp_path):
    (tmp_path / 'bad.obj').write_text('v 0 0 0\nv 1 0 0\nf 1 2 9\n')
    with pytest.raises(ValueError, match=r'bad\.obj line 3: face index 9 out of range'):
        main(['relax', str(tmp_path / 'bad.obj')])


def test_relax_a_net_file_in_a_subprocess(tmp_path):
    path, *_ = write_quad_net(tmp_path, 'obj', n=4, seed=1)
    done = subprocess.run(
        [sys.executable, '-m', 'ase_maud', 'relax', path.name, '--fixed', 'fixed.txt',
         '--fmax', '1e-6', '--traj', 'out.traj', '--quiet'],
        cwd=tmp_path, capture_output=True, text=True, check=True)
    assert done.stdout.startswith('converged: net.obj 16 points')
    assert read_net(tmp_path / 'out.traj').calc.springs.shape == (24, 2)


@pytest.mark.parametrize('every_help', ['relax', 'show', 'classify', 'bench', 'backends'])
def test_every_command_has_help_with_an_example(capsys, every_help):
    with pytest.raises(SystemExit) as exit:
        main([every_help, '--help'])
    assert exit.value.code == 0
    assert f'examples:\n  ase-maud {every_help}' in capsys.readouterr().out


@pytest.fixture(scope='module')
def relaxation(tmp_path_factory):
    """Trajectories of a 2D and a 3D net relaxed by the CLI."""
    folder = tmp_path_factory.mktemp('relaxation')
    trajectories = {}
    for dim, flat in ((2, True), (3, False)):
        path, *_ = write_quad_net(folder, 'obj', n=4, seed=dim, flat=flat)
        trajectories[dim] = folder / f'net{dim}.traj'
        assert main(['relax', str(path), '--fixed', str(folder / 'fixed.txt'), '--fmax',
                     '1e-8', '--traj', str(trajectories[dim]), '--quiet']) == 0
    return trajectories


@pytest.mark.parametrize('dim', [2, 3])
def test_show_draws_png_and_gif(tmp_path, capsys, relaxation, dim):
    png, gif = tmp_path / 'net.png', tmp_path / 'run.gif'
    assert main(['show', str(relaxation[dim]), '--frame', '0', '-o', str(png)]) == 0
    assert main(['show', str(relaxation[dim]), '--gif', '-o', str(gif)]) == 0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and png.stat().st_size > 20_000
    assert gif.read_bytes()[:6] == b'GIF89a' and gif.stat().st_size > 20_000
    out = capsys.readouterr().out
    assert f'wrote {png}' in out and f'wrote {gif} (' in out


def test_show_writes_beside_the_file_by_default(tmp_path):
    path, *_ = write_quad_net(tmp_path, 'mesh2.json', n=4)
    assert main(['show', str(path)]) == 0
    assert (tmp_path / 'net.mesh2.png').read_bytes()[:4] == b'\x89PNG'


def test_classify_a_relaxed_net_is_a_minimum(capsys, relaxation):
    assert main(['classify', str(relaxation[3])]) == 0
    verdict, eigenvalues = capsys.readouterr().out.splitlines()
    assert verdict.startswith('minimum: net3.traj 16 points, 12 free non-rigid modes')
    values = [float(v) for v in eigenvalues.split(':')[1].split()]
    assert len(values) == 6 and 0 < values[0] == min(values)


def test_classify_the_cage_centre_is_a_saddle_of_index_1(tmp_path, capsys):
    atoms = build('cage', 8)
    atoms.positions[-1] = 0.0   # the centre: stationary by symmetry
    write_net(tmp_path / 'cage.traj', atoms)
    assert main(['classify', str(tmp_path / 'cage.traj'), '-k', '3']) == 0
    verdict, eigenvalues = capsys.readouterr().out.splitlines()
    assert verdict.startswith('saddle of index 1: cage.traj 11 points, 3 free non-rigid')
    values = [float(v) for v in eigenvalues.split(':')[1].split()]
    assert values[0] < 0 < values[1]


def test_classify_says_not_stationary(tmp_path, capsys):
    path, *_ = write_quad_net(tmp_path, 'obj', n=4)
    assert main(['classify', str(path), '--fixed', str(tmp_path / 'fixed.txt')]) == 1
    assert capsys.readouterr().out.startswith('not stationary (fmax ')
