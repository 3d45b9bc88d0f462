"""Maud under ASE's drivers and constraints: NEB (ASE's Au on Al(100)
tutorial, dev/neb_tutorial.py), MinimaHopping, and FixedPlane / Hookean, each checked against an
ASE optimiser from the same start."""

import importlib.util

import numpy as np
import pytest
from ase.constraints import FixedPlane, Hookean
from ase.optimize import BFGS, FIRE

from ase_maud import Maud
from ase_maud.scenes.catalogue import build

from helpers import ROOT

_SPEC = importlib.util.spec_from_file_location(
    'neb_tutorial', ROOT / 'dev' / 'neb_tutorial.py')
neb_tutorial = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(neb_tutorial)


@pytest.mark.integration
@pytest.mark.parametrize('seed', [0, 1])
def test_neb_tutorial_converges_in_no_more_steps_than_fire(seed):
    fire = neb_tutorial.relax_band(FIRE, seed)
    maud = neb_tutorial.relax_band(Maud, seed)
    assert fire[0] and maud[0]
    assert maud[1] <= fire[1]
    # The same band: the barrier agrees to the resolution fmax 0.05 allows.
    assert maud[2] == pytest.approx(fire[2], abs=5e-3)


def test_neb_gets_the_stationary_target_and_says_so(tmp_path):
    band, _ = neb_tutorial.tutorial_band(0)
    log = tmp_path / 'neb.log'
    opt = Maud(band, logfile=str(log))
    assert opt.target == 'stationary'
    assert opt.rule.image_size == len(band.images[0])
    assert "target='stationary'" in log.read_text()
    assert Maud(band, logfile=None, target='minimum').target == 'minimum'


def _same_minimum_as_bfgs(atoms, fmax=1e-6):
    reference = atoms.copy()
    reference.calc = atoms.calc.__class__(**atoms.calc.parameters)
    reference.set_constraint([c.copy() for c in atoms.constraints])
    BFGS(reference, logfile=None).run(fmax=fmax, steps=5000)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=fmax, steps=5000)
    e, e_ref = atoms.get_potential_energy(), reference.get_potential_energy()
    assert e == pytest.approx(e_ref, rel=1e-8)
    return reference


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_fixed_plane_keeps_points_on_their_planes(seed):
    atoms = build('all_pairs', 6, seed=seed)
    start = atoms.get_positions()
    normal = np.random.default_rng(seed).normal(size=3)  # an oblique plane
    normal /= np.linalg.norm(normal)
    atoms.set_constraint(FixedPlane([0, 1], normal))
    reference = _same_minimum_as_bfgs(atoms)
    for relaxed in (atoms, reference):
        off_plane = (relaxed.positions[:2] - start[:2]) @ normal
        np.testing.assert_allclose(off_plane, 0.0, atol=1e-12)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_hookean_tether_gives_bfgs_minimum(seed):
    atoms = build('chain', 8, seed=seed)
    anchor = atoms.positions[0] + 0.5
    atoms.set_constraint(Hookean(a1=0, a2=anchor, rt=0.0, k=2.0))
    _same_minimum_as_bfgs(atoms)


@pytest.mark.integration
def test_minima_hopping_runs_with_maud(tmp_path, monkeypatch):
    from ase.optimize.minimahopping import MinimaHopping

    monkeypatch.chdir(tmp_path)
    atoms = build('all_pairs', 7, seed=3)
    atoms.set_masses(np.ones(len(atoms)))
    hop = MinimaHopping(atoms, optimizer=Maud, fmax=1e-3, T0=0.5, timestep=0.05,
                        mdmin=2, minima_threshold=1e-3, logfile='hop.log')
    hop(totalsteps=3)
    found = [line for line in (tmp_path / 'hop.log').read_text().splitlines()
             if 'Found a new minimum' in line or 'Already found' in line]
    assert found, 'MinimaHopping found no minimum'
    # Every minimum it kept is one: fmax at the optimiser's level.
    from ase.io import read
    for minimum in read('minima.traj', index=':'):
        minimum.calc = atoms.calc.__class__(**atoms.calc.parameters)
        assert np.linalg.norm(minimum.get_forces(), axis=1).max() < 1e-3
