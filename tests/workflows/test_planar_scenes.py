"""A planar scene under ASE's basin hopping stays in its plane."""

import numpy as np
from ase.optimize.basin import BasinHopping

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


def test_basin_hopping_on_a_plane(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    atoms = build('all_pairs2d', 7, seed=2)
    np.random.seed(3)
    with BasinHopping(atoms, temperature=1.0, dr=0.5, optimizer=Maud, fmax=1e-4,
                      logfile=None, optimizer_logfile=None, trajectory=None,
                      local_minima_trajectory=None) as hopping:
        hopping.run(4)
        energy, best = hopping.get_minimum()
    assert np.isfinite(energy)
    assert np.ptp(best.positions[:, 2]) == 0
