"""ASE's conventions for an optimizer, with Maud (docs/guide_ase.md): ``fmax=0``
takes every step asked, an unreadable restart file raises ASE's RestartError,
an Optimizable of any number of coordinates, and a run under a Filter, a cell
filter or a NEB broken off and carried on (``Maud.resume``, or ASE's recipe:
the last frame and ``restart=``) repeats the uninterrupted run."""

import json

import numpy as np
import pytest
from ase.build import add_adsorbate, bulk, fcc100
from ase.calculators.emt import EMT
from ase.constraints import FixAtoms
from ase.filters import Filter, FrechetCellFilter, UnitCellFilter
from ase.io import read
from ase.mep import NEB
from ase.optimize import BFGS, RestartError
from ase.test.optimize.test_pure import BoothFunctionOptimizable

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('seed', [0, 1])
def test_fmax_zero_takes_every_step_asked(seed):
    steps = int(np.random.default_rng(seed).integers(3, 9))
    atoms = build('hanging_net', 5, seed=seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=0, steps=steps) is False
        assert opt.nsteps == steps
        assert sum(1 for _ in opt.irun(fmax=0.0, steps=2)) == 3   # before each step, and after
        assert opt.nsteps == steps + 2


@pytest.mark.parametrize('text, match', [
    ('hello world\n', "Could not decode restart file '.*maud.json' as JSON"),
    ('{"format": "maud-restart-1"}', "restart file '.*maud.json' was not written by this"),
])
def test_an_unreadable_restart_file_raises_restart_error(tmp_path, text, match):
    restart = tmp_path / 'maud.json'
    restart.write_text(text)
    atoms = build('ring', 6, seed=2)
    start = atoms.positions.copy()
    with pytest.raises(RestartError, match=match) as raised:
        Maud(atoms, logfile=None, restart=restart)
    assert isinstance(raised.value, ValueError)   # as before: a bad file given
    np.testing.assert_array_equal(atoms.positions, start)


def test_a_damaged_restart_field_raises_restart_error_naming_it(tmp_path):
    restart = tmp_path / 'maud.json'
    with Maud(build('ring', 6, seed=3), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=3)
    document = json.loads(restart.read_text())
    document['gamma'] = -1.0
    restart.write_text(json.dumps(document))
    with pytest.raises(RestartError, match=r"is damaged: 'gamma' must be a positive"):
        Maud(build('ring', 6, seed=3), logfile=None, restart=restart)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_two_coordinates_reach_booths_minimum_like_bfgs(seed):
    start = np.random.default_rng(seed).uniform(-5, 5, size=2)
    found = {}
    for opt in (Maud, BFGS):
        target = BoothFunctionOptimizable(start.copy())
        with opt(target, logfile=None) as dyn:
            assert dyn.run(fmax=1e-8, steps=500)
        found[opt.__name__] = target.xy.copy()
    np.testing.assert_allclose(found['Maud'], [1, 3], atol=1e-8)
    np.testing.assert_allclose(found['Maud'], found['BFGS'], atol=1e-8)


# -- runs broken off and carried on ----------------------------------------------------

def _gold(seed):
    atoms = bulk('Au', cubic=True) * (2, 1, 1)
    atoms.rattle(stdev=0.05, seed=seed)
    atoms.cell *= 1.02
    atoms.calc = EMT()
    return atoms


SYSTEMS = {
    'Filter': lambda atoms: Filter(atoms, indices=[0, 2, 3, 5, 6]),
    'UnitCellFilter': UnitCellFilter,
    'FrechetCellFilter': lambda atoms: FrechetCellFilter(atoms, exp_cell_factor=1.0),
}


def _run(system, steps, path, restart=True, **kwargs):
    """``steps`` steps of Maud on ``system`` with its files in ``path``."""
    with Maud(system, logfile=None, trajectory=str(path / 'maud.traj'),
              restart=str(path / 'maud.json') if restart else None, **kwargs) as opt:
        opt.run(fmax=0, steps=steps)
    return opt


@pytest.mark.parametrize('recipe', ['resume', 'ase'])
@pytest.mark.parametrize('kind', sorted(SYSTEMS))
def test_a_filtered_run_carried_on_repeats_the_uninterrupted_one(tmp_path, kind, recipe):
    seed = sorted(SYSTEMS).index(kind)
    rng = np.random.default_rng(seed)
    first, total = int(rng.integers(2, 5)), 9
    (tmp_path / 'whole').mkdir()
    (tmp_path / 'cut').mkdir()
    whole = _gold(seed)
    _run(SYSTEMS[kind](whole), total, tmp_path / 'whole', restart=False)
    _run(SYSTEMS[kind](_gold(seed)), first, tmp_path / 'cut')
    if recipe == 'resume':
        atoms = _gold(seed)   # at the start: resume takes the last frame
        with Maud.resume(SYSTEMS[kind](atoms), restart=str(tmp_path / 'cut/maud.json'),
                         trajectory=str(tmp_path / 'cut/maud.traj'), logfile=None) as opt:
            opt.run(fmax=0, steps=total - first)
    else:   # ASE's: the last frame, then restart= the file
        atoms = read(tmp_path / 'cut/maud.traj', index=-1)
        atoms.calc = EMT()
        _run(SYSTEMS[kind](atoms), total - first, tmp_path / 'cut', append_trajectory=True)
    np.testing.assert_allclose(atoms.cell, whole.cell, atol=1e-10)
    np.testing.assert_allclose(atoms.positions, whole.positions, atol=1e-10)
    frames = read(tmp_path / 'cut/maud.traj', index=':')
    expected = read(tmp_path / 'whole/maud.traj', index=':')
    assert len(frames) == len(expected)


def _band(seed):
    """A NEB of 3 moving images: Au hopping on Al(100), the slab held."""
    slab = fcc100('Al', size=(2, 2, 3))
    add_adsorbate(slab, 'Au', 1.7, 'hollow')
    slab.center(axis=2, vacuum=4.0)
    slab.set_constraint(FixAtoms(mask=[atom.tag > 1 for atom in slab]))
    final = slab.copy()
    final[-1].x += slab.get_cell()[0, 0] / 2
    images = [slab] + [slab.copy() for _ in range(3)] + [final]
    for image in images:
        image.calc = EMT()
    band = NEB(images)
    band.interpolate()
    rng = np.random.default_rng(seed)
    for image in images[1:-1]:
        image.positions[-1] += rng.normal(scale=0.02, size=3)
    return band


@pytest.mark.parametrize('seed', [0, 1])
def test_a_neb_carried_on_repeats_the_uninterrupted_run(tmp_path, seed):
    first, total = int(np.random.default_rng(seed).integers(2, 5)), 8
    (tmp_path / 'whole').mkdir()
    (tmp_path / 'cut').mkdir()
    whole = _band(seed)
    _run(whole, total, tmp_path / 'whole', restart=False)
    _run(_band(seed), first, tmp_path / 'cut')
    band = _band(seed)
    with Maud.resume(band, restart=str(tmp_path / 'cut/maud.json'),
                     trajectory=str(tmp_path / 'cut/maud.traj'), logfile=None) as opt:
        opt.run(fmax=0, steps=total - first)
    for image, expected in zip(band.images, whole.images, strict=True):
        np.testing.assert_allclose(image.positions, expected.positions, atol=1e-10)
    assert (len(read(tmp_path / 'cut/maud.traj', index=':'))
            == len(read(tmp_path / 'whole/maud.traj', index=':')))
