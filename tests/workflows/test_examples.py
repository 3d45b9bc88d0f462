"""The runnable examples run, and say what they should."""

import pytest

from helpers import run_example


@pytest.mark.integration
def test_saddle_and_minima(monkeypatch, tmp_path, capsys):
    run_example('saddle_and_minima.py', [], monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert out.count('index 1 (saddle') == 2
    assert out.count('index 0 (minimum)') == 4
    assert (tmp_path / 'saddle_and_minima.png').stat().st_size > 0


def test_classify_large_net(monkeypatch, tmp_path, capsys):
    run_example('classify_large_net.py', ['--size', '8', '--k', '4'],
                monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert 'net2d 8: 64 points' in out
    assert 'relaxed: converged=True' in out
    assert 'classified: minimum (index 0)' in out


def test_form_finding(monkeypatch, tmp_path, capsys):
    """The canopy hangs from its outer rim: the reactions balance its load,
    the cables round the opening carry it, and the files are written."""
    run_example('form_finding.py', ['--weight', '0.3'], monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert 'canopy.obj: 100 points, 180 members, 36 supports, a = 0.0' in out
    assert '4 cables round the opening at q = 3.0' in out
    balance = float(out.split('reactions + loads = ')[1].split()[0])
    assert balance < 1e-9 * 0.3 * 64
    assert float(out.split('sag at the opening: ')[1].split()[0]) > 0.1
    for name in ('canopy_forces.csv', 'canopy.json', 'canopy.png'):
        assert (tmp_path / name).stat().st_size > 0
