"""benchmarks/kernel_throughput.py runs on a small size."""

import pytest

from helpers import run_example


def test_kernel_throughput(monkeypatch, tmp_path, capsys):
    pytest.importorskip('numba')
    run_example('kernel_throughput.py', ['--sizes', '300', '--seconds',
                                         '0.05', '--out', 'k.csv'],
                monkeypatch, tmp_path, folder='benchmarks')
    assert (tmp_path / 'k.csv').read_text().count('\n') >= 3
