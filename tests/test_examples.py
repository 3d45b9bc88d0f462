"""The runnable examples run, and say what they should."""

import runpy
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parent.parent


def run_example(name, argv, monkeypatch, tmp_path, folder='examples'):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, 'argv', [name, *argv])
    runpy.run_path(str(ROOT / folder / name), run_name='__main__')


def test_saddle_and_minima(monkeypatch, tmp_path, capsys):
    run_example('saddle_and_minima.py', [], monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert out.count('index 1 (saddle') == 2
    assert out.count('index 0 (minimum)') == 4
    assert (tmp_path / 'saddle_and_minima.png').stat().st_size > 0


def test_kernel_throughput(monkeypatch, tmp_path, capsys):
    pytest.importorskip('numba')
    run_example('kernel_throughput.py', ['--sizes', '300', '--seconds',
                                         '0.05', '--out', 'k.csv'],
                monkeypatch, tmp_path, folder='tools')
    assert (tmp_path / 'k.csv').read_text().count('\n') >= 3
