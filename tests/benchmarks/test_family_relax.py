"""benchmarks/family_relax.py: one row per run, Maud (with two stiffness models) and
L-BFGS-B on a family's small draw and on a catalogue scene, all converged to the same
minimum, calls counted with the start's, and an --out that exists is refused before any
work."""

import csv

import pytest

from helpers import run_example


@pytest.mark.integration
def test_rows_of_both_optimizers_and_an_existing_out_is_refused(monkeypatch, tmp_path):
    run_example('family_relax.py', ['--families', 'hub_net', '--seeds', '5', '--sizes', '60',
                                    '90', '--scenes', 'hub_net:4', '--optimizers', 'Maud',
                                    'L-BFGS-B', '--models', 'auto', 'near', '--fmax', '1e-6',
                                    '--out', 'rows.csv'],
                monkeypatch, tmp_path, folder='benchmarks')
    rows = list(csv.DictReader((tmp_path / 'rows.csv').open()))
    assert [(r['scene'], r['optimizer']) for r in rows] == [
        ('hub_net', 'Maud'), ('hub_net', 'Maud-near'), ('hub_net', 'L-BFGS-B')] * 2
    assert [r['seed'] for r in rows] == ['4'] * 3 + ['5'] * 3
    for maud, near, lbfgsb in zip(rows[::3], rows[1::3], rows[2::3], strict=True):
        for run in (maud, near):
            assert run['converged'] == lbfgsb['converged'] == 'True'
            assert run['natoms'] == lbfgsb['natoms']
            assert float(run['energy']) == pytest.approx(float(lbfgsb['energy']), rel=1e-8)
            assert 2 <= int(run['calls']) < int(lbfgsb['calls'])
    before = (tmp_path / 'rows.csv').read_text()
    with pytest.raises(SystemExit, match='exists'):
        run_example('family_relax.py', ['--out', 'rows.csv'], monkeypatch, tmp_path,
                    folder='benchmarks')
    assert (tmp_path / 'rows.csv').read_text() == before
