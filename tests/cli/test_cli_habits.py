"""The command line's habits: --version, usage errors exit 2, did you mean,
classify and show take the loads, the progress bar's share in log fmax, the
compile notice whenever a kernel compiles, reports that do not contradict
themselves."""

import io
import math

import numpy as np
import pytest

from ase_maud import __version__
from ase_maud.checks import did_you_mean
from ase_maud.cli.command import main
from ase_maud.cli.relax import convergence_share
from ase_maud.cli.saddles import counted
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.kernel_cache import COMPILE_NOTICE, compile_notice
from ase_maud.saddles.attempts import Attempt


def test_version(capsys):
    with pytest.raises(SystemExit) as exit:
        main(['--version'])
    assert exit.value.code == 0
    assert capsys.readouterr().out.strip() == f'ase-maud {__version__}'


def test_bare_command_is_a_usage_error_with_the_help_on_stderr(capsys):
    assert main([]) == 2
    captured = capsys.readouterr()
    assert captured.out == '' and captured.err.startswith('usage: ase-maud')


@pytest.mark.parametrize('argv, suggestion', [
    (['rlax'], "did you mean 'relax'?"),
    (['relax', '--scene', 'rng'], "did you mean 'ring'?"),
    (['show', 'x.traj', '--view', 'isp'], "did you mean 'iso'?"),
])
def test_a_mistyped_choice_gets_a_suggestion_and_status_2(capsys, argv, suggestion):
    with pytest.raises(SystemExit) as exit:
        main(argv)
    assert exit.value.code == 2
    assert suggestion in capsys.readouterr().err


def test_a_mistyped_rule_gets_a_suggestion(tmp_path, capsys):
    net = tmp_path / 'net.obj'
    net.write_text('v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n')
    assert main(['relax', str(net), '--fix', 'outr', '--quiet',
                 '--traj', str(tmp_path / 'r.traj')]) == 2
    assert "did you mean 'outer'?" in capsys.readouterr().err
    assert did_you_mean('zzzz', ('boundary', 'outer')) == ''


def loaded_grid(tmp_path, rng):
    """A 6 x 6 OBJ grid (no loads in the file), relaxed at a = 0 under a
    random vertical load, written back as OBJ: the load is lost."""
    n = 6
    lines = [f'v {i} {j} 0' for i in range(n) for j in range(n)]
    lines += [f'f {i * n + j + 1} {(i + 1) * n + j + 1} {(i + 1) * n + j + 2} {i * n + j + 2}'
              for i in range(n - 1) for j in range(n - 1)]
    source = tmp_path / 'grid.obj'
    source.write_text('\n'.join(lines) + '\n')
    load = ['0', '0', f'{-rng.uniform(0.1, 1.0):.6f}']
    out = tmp_path / 'hung.obj'
    assert main(['relax', str(source), '--fix', 'boundary', '--a', '0', '--load', *load,
                 '--quiet', '--traj', str(tmp_path / 'r.traj'), '--out', str(out)]) == 0
    return out, load


def test_classify_takes_the_loads(tmp_path, capsys):
    out, load = loaded_grid(tmp_path, np.random.default_rng(0))
    common = ['classify', str(out), '--fix', 'boundary', '--a', '0', '--fmax', '1e-8']
    assert main(common) == 1   # without its load the hung net is not in balance
    assert main([*common, '--load', *load]) == 0
    assert capsys.readouterr().out.count('minimum') >= 1


def test_show_takes_the_loads(tmp_path, capsys):
    pytest.importorskip('matplotlib')
    out, load = loaded_grid(tmp_path, np.random.default_rng(1))
    picture = tmp_path / 'hung.png'
    assert main(['show', str(out), '--fix', 'boundary', '--a', '0', '--load', *load,
                 '-o', str(picture)]) == 0
    assert picture.stat().st_size > 0


def test_q_table_or_number_is_taken_by_classify(tmp_path):
    out, load = loaded_grid(tmp_path, np.random.default_rng(2))
    # every q doubled: the hung form is no longer in balance
    assert main(['classify', str(out), '--fix', 'boundary', '--a', '0', '--fmax', '1e-8',
                 '--load', *load, '--q', '2']) == 1


@pytest.mark.parametrize('seed', range(3))
def test_convergence_share_is_the_way_in_log_fmax(seed):
    rng = np.random.default_rng(seed)
    first, goal = 10 ** rng.uniform(0, 2), 10 ** rng.uniform(-9, -3)
    assert convergence_share(first, first, goal) == 0.0
    assert convergence_share(first, 2 * first, goal) == 0.0
    assert convergence_share(first, goal, goal) == 1.0
    assert convergence_share(first, goal / 3, goal) == 1.0
    assert convergence_share(first, math.sqrt(first * goal), goal) == pytest.approx(0.5)
    now = np.sort(10 ** rng.uniform(np.log10(goal), np.log10(first), 20))[::-1]
    shares = [convergence_share(first, f, goal) for f in now]
    assert np.all(np.diff(shares) >= 0)
    # its derivative in log fmax is the constant -1 / log(first / goal)
    h, f = 1e-6, now[10]
    slope = (convergence_share(first, f * math.exp(h), goal)
             - convergence_share(first, f * math.exp(-h), goal)) / (2 * h)
    assert slope == pytest.approx(-1 / math.log(first / goal), rel=1e-6)


def test_compile_notice_is_said_once_when_an_ase_maud_kernel_compiles():
    numba = pytest.importorskip('numba')

    def ours(x):
        return x + 1

    def theirs(x):
        return x * 2

    ours.__module__ = 'ase_maud.fake_kernels'
    ours_jit, theirs_jit = numba.njit(ours), numba.njit(theirs)
    stream = io.StringIO()
    with compile_notice(stream):
        theirs_jit(1.0)
    assert stream.getvalue() == ''   # not one of ours
    with compile_notice(stream):
        ours_jit(1.0)
        ours_jit(1)   # a second signature: compiles again, said once
    assert stream.getvalue() == COMPILE_NOTICE + '\n'
    again = io.StringIO()
    with compile_notice(again):
        ours_jit(2.0)   # compiled already: nothing to say
    assert again.getvalue() == ''


def test_reports_do_not_contradict_themselves():
    assert counted(1, 'minimum', 'minima') == '1 minimum'
    assert counted(2, 'minimum', 'minima') == '2 minima'
    assert counted(0, 'saddle') == '0 saddles'
    attempt = Attempt('local', 4)
    assert '(0 points)' not in attempt.describe()
    assert 'whole net' in attempt.describe()
    attempt.region = 7
    assert 'local at point 4 (7 points)' in attempt.describe()


def test_write_and_read_keep_the_load_free_obj(tmp_path):
    """(write_net of a net read from OBJ keeps its faces: a check of the
    habit 'what goes in comes out'.)"""
    out, _ = loaded_grid(tmp_path, np.random.default_rng(3))
    atoms = read_net(out)
    write_net(tmp_path / 'again.obj', atoms)
    assert (tmp_path / 'again.obj').read_text().count('\nf ') == 25


def test_a_compressed_net_relaxed_with_repulsion_is_said_to_be_a_stationary_point(tmp_path,
                                                                                  capsys):
    out, load = loaded_grid(tmp_path, np.random.default_rng(7))
    assert main(['relax', str(out), '--fix', 'boundary', '--a', '0.2', '--q', '-1', '--load',
                 *load, '--quiet', '--traj', str(tmp_path / 's.traj')]) == 0
    captured = capsys.readouterr()
    assert '(compression)' in captured.out
    assert 'a stationary point of the energy), not a minimum' in captured.err
    assert main(['relax', str(out), '--fix', 'boundary', '--a', '0', '--q', '-1', '--load',
                 *load, '--quiet', '--traj', str(tmp_path / 't.traj')]) == 0
    assert 'not a minimum' not in capsys.readouterr().err   # a = 0: the solve says it all
