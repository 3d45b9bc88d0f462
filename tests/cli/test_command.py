"""The ase-maud command: help, relax (a scene or a net file), show, classify,
scene selection."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from ase.io import read
from ase.optimize import BFGS

from ase_maud.cli import command, options
from ase_maud.cli import saddles as saddles_cli
from ase_maud.cli.command import main
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.scenes.catalogue import SUITE, build, scene_sizes
from ase_maud.scenes.saddle_scenes import rim

from helpers import relaxed_in_python, rule_a, write_quad_net


def test_no_command_prints_help(capsys):
    assert main([]) == 2   # a usage error, the help on stderr
    out = capsys.readouterr().err
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
    parser = command.build_parser()
    assert parser.parse_args(['relax']).threads is None  # environment alone
    assert parser.parse_args(['bench']).threads == 1
    assert parser.parse_args(['backends', '--threads', '2']).threads == 2


def test_python_m_runs_the_command():
    done = subprocess.run([sys.executable, '-m', 'ase_maud', '--help'],
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
    assert options.size_option('12') == 12 and options.size_option('CH4') == 'CH4'


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


def force_density_solution(positions, springs, fixed, q, loads):
    """The free points' equilibrium of springs ``q L**2 / 2`` (Q = 1) and
    loads alone, the fixed points where they are: the linear system
    ``(L_q x)_free = loads_free`` solved densely."""
    n = len(positions)
    laplacian = np.zeros((n, n))
    for (i, j), qs in zip(springs, q, strict=True):
        laplacian[[i, j, i, j], [i, j, j, i]] += [qs, qs, -qs, -qs]
    free = np.setdiff1d(np.arange(n), fixed)
    x = np.array(positions, dtype=float)
    rhs = loads[free] - laplacian[np.ix_(free, fixed)] @ x[fixed]
    x[free] = np.linalg.solve(laplacian[np.ix_(free, free)], rhs)
    return x


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_relax_with_a_load_on_every_free_point(tmp_path, capsys, seed):
    """``--load X Y Z`` on a flat net read from a file: with a tiny ``a`` the
    relaxed net is the force-density solution under that load (solved here
    directly); the load goes with the trajectory and the COMPAS file
    written."""
    path, positions, springs, fixed = write_quad_net(tmp_path, 'obj', seed=seed, flat=True)
    load = np.random.default_rng(seed).normal(0.0, 0.3, 3)
    traj, out = tmp_path / 'out.traj', tmp_path / 'relaxed.json'
    assert main(['relax', str(path), '--fixed', str(tmp_path / 'fixed.txt'), '--a', '1e-4',
                 '--load', *map(str, load), '--fmax', '1e-10', '--traj', str(traj),
                 '--out', str(out), '--quiet']) == 0
    loads = np.where(np.isin(np.arange(25), fixed)[:, None], 0.0, load)
    expected = force_density_solution(positions, springs, fixed, np.ones(len(springs)), loads)
    for relaxed in (read_net(traj), read_net(out, a=1e-4)):
        assert relaxed.calc.dim == 3
        np.testing.assert_array_equal(relaxed.calc.parameters['loads'], loads)
        np.testing.assert_allclose(relaxed.positions, expected, rtol=0, atol=1e-8)


def test_the_default_scene_hangs_under_its_weight(tmp_path, capsys):
    """``ase-maud relax``: the weighted net, at the minimum BFGS finds from the
    same start, every free point below where it hangs without its weight."""
    traj = tmp_path / 'maud.traj'
    assert main(['relax', '--fmax', '1e-7', '--traj', str(traj), '--quiet']) == 0
    assert capsys.readouterr().out.startswith('converged: weighted_net 64 points')
    relaxed = read_net(traj)
    reference = build('weighted_net')
    with BFGS(reference, logfile=None) as opt:
        assert opt.run(fmax=1e-7, steps=2000)
    assert relaxed.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-10)
    np.testing.assert_allclose(relaxed.positions, reference.positions, atol=1e-6)
    # The free points hang 0.32 a or more lower: fmax 1e-5 (275 BFGS steps where
    # 1e-7 takes 1003) puts the unloaded net within 5e-6 a of its minimum.
    unloaded = build('hanging_net')
    with BFGS(unloaded, logfile=None) as opt:
        assert opt.run(fmax=1e-5, steps=2000)
    free = np.flatnonzero(relaxed.calc.parameters['loads'][:, 2])
    assert len(free) == 36 and (relaxed.positions[free, 2] < unloaded.positions[free, 2]).all()


def test_a_free_net_under_a_load_is_refused_before_the_first_step(tmp_path, capsys):
    path, *_ = write_quad_net(tmp_path, 'obj')
    assert main(['relax', str(path), '--load', '0', '0', '-1', '--traj',
                 str(tmp_path / 'o.traj'), '--quiet']) == 2
    error = capsys.readouterr().err
    assert re.match(r'ase-maud: error: before the first step: .*loads sum to .* drifts for '
                    r'ever', error) and error.count('\n') == 1


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
                 '--progress', '--log', str(log), '--steps', '321']) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith('converged: net.obj 16 points')   # only the summary
    steps = int(captured.out.split(' steps,')[0].rsplit(' ', 1)[1])
    assert f'step {steps}/321, fmax' in captured.err   # the bar tracks fmax; steps of the cap
    assert 'fmax' in captured.err and '(goal 0.0001)' in captured.err
    assert 'energy' in captured.err
    assert 'Maud:' in log.read_text()


@pytest.mark.parametrize('option', ['--fixed', '--fix'])
def test_relax_net_options_need_a_file(capsys, option):
    with pytest.raises(SystemExit):
        main(['relax', option, 'fixed.txt'])
    assert '--fix and --dim need NET_FILE' in capsys.readouterr().err


@pytest.mark.parametrize('argv, message', [
    (['relax', '--out', 'relaxed.foo'], "--out 'relaxed.foo': no net format has the suffix "
     "'.foo'; use .obj, .json, .traj, .xyz or another format ASE writes"),
    (['relax', '--out', 'relaxed'], "--out 'relaxed': no net format has the suffix ''"),
    (['relax', '--out', '.'], "--out '.' is a directory; give a file name"),
    (['relax', '--out', 'missing/r.obj'], "--out 'missing/r.obj': the directory 'missing' "
     'does not exist'),
    (['relax', '--traj', 'missing/m.traj'], "--traj 'missing/m.traj': the directory"),
    (['relax', '--log', '.'], "--log '.' is a directory"),
    (['relax', 'absent.obj'], 'absent.obj: No such file or directory'),
    (['relax', 'bad.obj'], 'bad.obj line 3: face index 9 out of range'),
    (['relax', 'net.obj', '--fixed', 'absent.txt'],
     "fixed='absent.txt' is neither a rule (boundary, outer, leaves) nor a file"),
    (['classify', 'bad.obj'], 'bad.obj line 3: face index 9 out of range'),
    (['show', 'net.obj', '-o', 'net.txt'], "--output 'net.txt': a picture is written as one "
     'of .'),
    (['show', 'net.obj', '--gif', '-o', 'net.png'], "--output 'net.png': an animation "
     '(--gif) is written as .gif'),
    (['bench', '--out', 'net.obj'], "--out 'net.obj': 'net.obj' is a file, not a directory"),
    (['backends', '--out', 'net.obj/sub'], "--out 'net.obj/sub': 'net.obj' is a file, not a "
     'directory'),
])
def test_errors_are_one_line_with_status_2(tmp_path, monkeypatch, capsys, argv, message):
    """Bad input is one line on stderr, exit status 2, found before any work
    (no trajectory, no picture, no benchmark output)."""
    monkeypatch.chdir(tmp_path)
    write_quad_net(tmp_path, 'obj', n=4)
    (tmp_path / 'bad.obj').write_text('v 0 0 0\nv 1 0 0\nf 1 2 9\n')
    before = sorted(tmp_path.iterdir())
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f'ase-maud: error: {message}')
    assert captured.err.count('\n') == 1 and captured.out == ''
    assert sorted(tmp_path.iterdir()) == before


def test_an_error_is_one_line_from_the_command(tmp_path):
    done = subprocess.run([sys.executable, '-m', 'ase_maud', 'relax', '--out', 'r.foo'],
                          cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stderr.startswith("ase-maud: error: --out 'r.foo': no net format")
    assert done.stderr.count('\n') == 1 and 'Traceback' not in done.stderr
    assert list(tmp_path.iterdir()) == []


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
                     '1e-8', '--traj', str(trajectories[dim]), '--quiet', '--a', '0.3']) == 0
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


@pytest.mark.parametrize('colour, view', [('length', 'top'), ('none', 'front'),
                                          ('force', 'side')])
def test_show_colours_and_views(tmp_path, capsys, relaxation, colour, view):
    svg = tmp_path / 'net.svg'
    assert main(['show', str(relaxation[3]), '--color', colour, '--view', view,
                 '-o', str(svg)]) == 0
    text = svg.read_text()
    assert text.startswith('<?xml') and ('spring length L' in text) == (colour == 'length')
    assert 'residual force' not in text   # relaxed to --fmax 1e-8: converged
    assert main(['show', str(relaxation[3]), '--frame', '0', '-o', str(svg)]) == 0
    assert 'residual force' in svg.read_text()


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


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_classify_judges_at_the_fmax_relaxed_to(tmp_path, capsys, seed):
    """A trajectory relaxed to --fmax 1e-2 is stationary at 1e-2 (stored in
    it), not at the default 1e-6 Q a, unless --fmax says otherwise."""
    path, *_ = write_quad_net(tmp_path, 'obj', n=4, seed=seed)
    traj = tmp_path / 'r.traj'
    assert main(['relax', str(path), '--fixed', str(tmp_path / 'fixed.txt'), '--a', '0.3',
                 '--fmax', '1e-2', '--traj', str(traj), '--quiet']) == 0
    fmax = np.linalg.norm(read(traj).get_forces(), axis=1).max()
    assert 1e-6 < fmax < 1e-2   # the default would judge otherwise
    capsys.readouterr()
    assert main(['classify', str(traj)]) == 0
    assert '(stationary up to 0.01, the fmax it was relaxed to)' in capsys.readouterr().out
    assert main(['classify', str(traj), '--fmax', f'{fmax / 2}']) == 1
    assert capsys.readouterr().out.startswith('not stationary (fmax ')
    assert main(['classify', str(traj), '--ftol', f'{fmax * 2}']) == 0


def test_classify_says_not_stationary(tmp_path, capsys):
    path, *_ = write_quad_net(tmp_path, 'obj', n=4)
    assert main(['classify', str(path), '--fixed', str(tmp_path / 'fixed.txt')]) == 1
    assert capsys.readouterr().out.startswith('not stationary (fmax ')


@pytest.mark.parametrize('argv, message', [
    (['bench', '--fmax', '-1'], 'ase-maud bench: error: argument --fmax: fmax must be'),
    (['backends', '--natoms', '-5'], 'ase-maud backends: error: argument --natoms: count'),
    (['classify', 'x.traj', '-k', '-3'], 'ase-maud classify: error: argument -k: count'),
    (['relax', '--load', '0', 'x', '0'], 'ase-maud relax: error: argument --load'),
    (['nope'], "ase-maud: error: argument COMMAND: invalid choice: 'nope'"),
])
def test_argument_errors_are_one_line_with_status_2(capsys, argv, message):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    error = capsys.readouterr().err
    assert stop.value.code == 2 and error.startswith(message) and error.count('\n') == 1
    assert error.rstrip().endswith('--help')


@pytest.mark.parametrize('seed, window, sweep', [(0, None, True), (1, None, True),
                                                 (2, 1.0, True), (3, 1.0, False)])
def test_saddles_prints_draws_and_writes_the_landscape(tmp_path, capsys, seed, window, sweep):
    """``ase-maud saddles`` relaxes the net, finds the landscape the library
    finds from the same minimum (with ``--window``, its rounds and its sweep
    too, or not with ``--no-sweep``), and writes the picture and its JSON."""
    import json

    from ase_maud import Maud
    from ase_maud.saddles.landscape import landscape

    atoms = build('all_pairs2d', 9, seed=seed)
    write_net(tmp_path / 'c.traj', atoms)
    out = tmp_path / 'graph.png'
    rounds = ([] if window is None else ['--window', str(window)]) + (
        [] if sweep else ['--no-sweep'])
    assert main(['saddles', str(tmp_path / 'c.traj'), '--modes', '2', '--out',
                 str(out), *rounds]) == 0
    lines = capsys.readouterr().out.splitlines()
    graph = json.loads(out.with_suffix('.json').read_text())
    assert out.stat().st_size > 0
    Maud(atoms, logfile=None).run(fmax=1e-6, steps=1000)
    found = landscape(atoms, modes=2, window=window, sweep=sweep)
    assert len(graph['minima']) == len(found.minima)
    saddle_lines = [line for line in lines if line.startswith('saddle ')]
    assert len(graph['saddles']) == len(found.saddles) == len(saddle_lines)
    assert lines[0].endswith("force calls' CPU:")   # the search's report: one line an attempt
    for kind in ('mode', 'local'):
        assert sum(line.startswith(f'  {kind} ') for line in lines) == len(
            [a for a in found.search.attempts if a.kind == kind])
    assert window is not None or len(found.search.attempts) == 2 * 2 + 1   # one round
    assert sorted(s['energy'] for s in graph['saddles']) == pytest.approx(
        sorted(s.get_potential_energy() for s in found.saddles), rel=1e-9)
    assert graph['failed'] == 0 and lines[-1].startswith(f"{len(found.minima)} minima")


def test_saddles_on_two_local_workers_writes_the_same_graph(tmp_path, capsys):
    pytest.importorskip('distributed')
    write_net(tmp_path / 'c.traj', build('all_pairs2d', 9, seed=2))
    graphs = []
    for spread in ([], ['--workers', '2']):
        out = tmp_path / f'graph{len(spread)}.png'
        assert main(['saddles', str(tmp_path / 'c.traj'), '--modes', '2', '--out',
                     str(out), *spread]) == 0
        graphs.append(json.loads(out.with_suffix('.json').read_text()))
    capsys.readouterr()
    assert graphs[0]['joins'] == graphs[1]['joins'] and graphs[0]['saddles']
    assert [s['energy'] for s in graphs[0]['saddles']] == pytest.approx(
        [s['energy'] for s in graphs[1]['saddles']], rel=1e-12)


@pytest.mark.integration
def test_saddles_takes_the_path_to_a_second_minimum_given_or_mirrored(tmp_path, capsys):
    """With no climbs and no local activation (--modes 0 --local 0),
    ``ase-maud saddles`` on a dome finds the
    saddle between it and a second minimum: its mirror image (--mirror) or
    the points of a file (--partner, the mirror image written by the
    library); both the saddle ``saddle_between`` finds from the same two
    minima (seeds 1-2 of 5 x 5 domes), verified index 1, joining two minima
    (not always the two given: the band's highest saddle may lie between two
    minima of the path)."""
    from ase_maud import Maud
    from ase_maud.analysis.stationary import classify
    from ase_maud.counting import fresh_copy
    from ase_maud.saddles.between_minima import mirrored, saddle_between

    for seed in (1, 2):
        first = rim(5, seed)
        write_net(tmp_path / f'dome{seed}.traj', first)
        assert Maud(first, logfile=None).run(fmax=1e-6, steps=5000)
        second = mirrored(first)
        write_net(tmp_path / f'mirror{seed}.traj', second)
        expected = saddle_between(first, second).saddle
        assert classify(fresh_copy(expected)).index == 1
        for how in (['--mirror'], ['--partner', str(tmp_path / f'mirror{seed}.traj')]):
            out = tmp_path / f'graph{seed}{len(how)}.png'
            assert main(['saddles', str(tmp_path / f'dome{seed}.traj'), '--modes', '0',
                         '--local', '0', '--out', str(out), *how]) == 0
            lines = capsys.readouterr().out.splitlines()
            assert any(line.startswith('  path ') for line in lines)
            graph = json.loads(out.with_suffix('.json').read_text())
            assert len(graph['saddles']) == 1 and len(set(graph['joins'][0])) == 2
            assert graph['saddles'][0]['energy'] == pytest.approx(
                expected.get_potential_energy(), rel=1e-8)


def test_saddles_names_a_partner_that_is_not_the_nets(tmp_path):
    """A --partner file with other points than the net's, or none, is named
    (no search runs with it)."""

    write_net(tmp_path / 'dome.traj', rim(5, 0))
    write_net(tmp_path / 'other.traj', rim(6, 0))
    base = ['saddles', str(tmp_path / 'dome.traj'), '--modes', '0', '--out',
            str(tmp_path / 'g.png')]
    with pytest.raises(ValueError, match="--partner .*other.traj' has 36 points, the net "
                       ".*has 25"):
        saddles_cli.saddles_command(command.build_parser().parse_args(
            [*base, '--partner', str(tmp_path / 'other.traj')]))
    with pytest.raises(ValueError, match="--partner .*none.traj': no such file"):
        options.check_outputs(command.build_parser().parse_args(
            [*base, '--partner', str(tmp_path / 'none.traj')]))
    assert not (tmp_path / 'g.png').exists()


def test_saddles_checks_its_output_first(tmp_path):
    with pytest.raises(ValueError, match='--out .*does not exist'):
        options.check_outputs(command.build_parser().parse_args(
            ['saddles', 'x.traj', '--out', str(tmp_path / 'no' / 'g.png')]))


def test_help_imports_nothing_heavy():
    """ase-maud --help imports argparse, not numpy, numba, ASE or matplotlib:
    it answers at once."""
    code = ('import sys\nfrom ase_maud.cli import main\n'
            'try:\n    main(["--help"])\nexcept SystemExit:\n    pass\n'
            'print(sorted({"numpy", "numba", "ase", "scipy", "matplotlib"} & set(sys.modules)))')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.startswith('usage: ase-maud') and done.stdout.endswith('[]\n')
