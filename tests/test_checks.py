"""The one rules table: each keyword accepted and refused by its rule."""

import os
import re
from pathlib import Path

import numpy as np
import pytest

from ase_maud import Maud, MaudCalculator
from ase_maud.checks import RULES, check
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('name, good, bad', [
    ('gamma', [0.5, 2, np.float32(1.0)], [0, -1, np.nan, None, True, '1']),
    ('memory', [0, 7, 7.0, np.int64(3), None], [1.5, -1, True, 'x']),
    ('maxstep_nn', [0.1, 0.49, None], [0.5, 0, 1]),
    ('target', ['minimum', 'stationary', None], ['max', 3, b'minimum']),
    ('method', ['tensor', 'scalar'], ['vector', None]),
    ('dim', [2, 3, np.int64(3)], [2.0, 4, True, None]),
    ('tol', [0, 0.0, 1e-3], [1.0, -1e-9, np.inf]),
    ('crossover', [None, 0, 5000], [-1, 2.5, 'x']),
    ('fmm_eps', [1e-6, 0.5], [0, 1.0]),
])
def test_rules_accept_and_refuse(name, good, bad):
    for value in good:
        checked = check(name, value)
        assert checked == value or (value is None and checked is None)
    for value in bad:
        with pytest.raises(ValueError, match=re.escape(
                f'{name} must be {RULES[name].accepted}, got {value!r}')):
            check(name, value)


def test_whole_numbers_come_back_as_int():
    assert type(check('memory', 7.0)) is int
    assert type(check('gamma', 2)) is float
    assert type(check('dim', np.int64(2))) is int


def test_the_calculator_and_the_optimizer_use_the_same_rule():
    with pytest.raises(ValueError, match=re.escape('tol must be ' + RULES['tol'].accepted)):
        MaudCalculator(tol=2.0)
    with pytest.raises(ValueError, match='^floor must be'):
        Maud(build('ring', 8), floor=2.0, logfile=None)


def test_an_unknown_calculator_parameter_is_named():
    with pytest.raises(ValueError, match="no parameter 'tole'"):
        MaudCalculator(tole=1e-3)


@pytest.mark.parametrize('argv, message', [
    (['bench', '--fmax', '-1'], 'fmax must be a positive finite number'),
    (['bench', '--fmax', '1e-3', '0'], 'fmax must be a positive finite number'),
    (['bench', '--energy-rtol', 'nan'], 'energy_rtol must be a positive finite number'),
    (['bench', '--seeds', '0', '-2'], 'seed must be a whole number >= 0'),
    (['backends', '--natoms', '-5'], 'count must be a whole number >= 1'),
    (['classify', 'net.obj', '-k', '-3'], 'count must be a whole number >= 1'),
    (['relax', '--steps', '-1'], 'steps must be a whole number >= 0'),
    (['relax', '--a', '-1'], 'a must be a finite number >= 0'),
    (['relax', '--threads', '0'], 'count must be a whole number >= 1'),
])
def test_command_line_values_follow_the_rules(argv, message, capsys):
    from ase_maud.cli.command import build_parser
    with pytest.raises(SystemExit):
        build_parser().parse_args(argv)
    assert message in capsys.readouterr().err


@pytest.mark.parametrize('value, directory, match', [
    ('.', False, "out '.' is a directory; give a file name"),
    ('missing/net.obj', False, "out 'missing/net.obj': the directory 'missing' does not exist"),
    ('file.txt/net.obj', False, "the directory 'file.txt' does not exist"),
    ('file.txt', True, "out 'file.txt': 'file.txt' is a file, not a directory"),
    ('file.txt/deeper/bench', True, "'file.txt' is a file, not a directory"),
    ('locked/net.obj', False, "the directory 'locked' is not writable"),
    ('locked/bench', True, "the directory 'locked' is not writable"),
])
def test_check_writable_refuses_what_cannot_be_written(tmp_path, monkeypatch, value,
                                                       directory, match):
    from ase_maud import checks
    from ase_maud.checks import check_writable
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'file.txt').write_text('')
    (tmp_path / 'locked').mkdir()
    access = os.access   # 'locked' is read-only, also to root
    monkeypatch.setattr(checks.os, 'access',
                        lambda path, mode: Path(path).name != 'locked' and access(path, mode))
    with pytest.raises(ValueError, match=re.escape(match)):
        check_writable('out', value, directory=directory)


@pytest.mark.parametrize('value, directory', [
    ('net.obj', False), ('sub/net.obj', False), ('.', True), ('new/deeper', True),
    ('sub', True)])
def test_check_writable_accepts_what_can_be_written(tmp_path, monkeypatch, value, directory):
    from ase_maud.checks import check_writable
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'sub').mkdir()
    assert check_writable('out', value, directory=directory) == Path(value)
    assert not (tmp_path / 'new').exists()   # checked, nothing made
