"""benchmarks/classify_paths.py: on small scenes of the families both paths of
``classify`` give the same verdict and lowest eigenvalue, the rows say what each
counted, and an --out that exists is refused before any work."""

import csv

import pytest

from helpers import run_example


@pytest.mark.integration
def test_both_paths_agree_and_an_existing_out_is_refused(monkeypatch, tmp_path):
    run_example('classify_paths.py', ['--families', 'random_tree', 'knn_cluster', '--seed',
                                      '3', '--sizes', '60', '80', '--out', 'rows.csv'],
                monkeypatch, tmp_path, folder='benchmarks')
    rows = list(csv.DictReader((tmp_path / 'rows.csv').open()))
    assert [r['method'] for r in rows] == ['lowest', 'iterative'] * 2
    for dense, iterative in zip(rows[::2], rows[1::2], strict=True):
        assert dense['verdict'] == iterative['verdict'] == 'minimum'
        assert float(iterative['lowest']) == pytest.approx(float(dense['lowest']), rel=1e-4)
        assert (int(dense['hessians']), int(dense['hvp_vectors'])) == (1, 0)
        assert int(iterative['hessians']) == 0 and int(iterative['hvp_vectors']) > 0
    before = (tmp_path / 'rows.csv').read_text()
    with pytest.raises(SystemExit, match='exists'):
        run_example('classify_paths.py', ['--out', 'rows.csv'], monkeypatch, tmp_path,
                    folder='benchmarks')
    assert (tmp_path / 'rows.csv').read_text() == before
