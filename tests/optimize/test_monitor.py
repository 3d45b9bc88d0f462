"""The run monitor (ase_maud.optimize.monitor): a run no force slows is
stopped, a spring-held one may grow, stagnation and creep are named at any
scale, and its state counts steps from a restart."""

import numpy as np
import pytest

from ase_maud import Maud, MaudError
from ase_maud.errors import DivergenceError, StagnationError
from ase_maud.optimize.monitor import ENERGY_PROGRESS, RunMonitor, measures
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('seed', [0, 1])
def test_a_creeping_run_is_stopped_at_any_scale(seed):
    # a ring flattened to 1e8 by 1e-8: the energy keeps falling, by ever
    # smaller fractions of its descent, while fmax stays near 4e7
    atoms = build('ring', 20, seed=seed)
    atoms.positions *= [1e8, 1e-8, 1.0]
    with Maud(atoms, logfile=None, patience=300) as opt:
        with pytest.raises(MaudError, match='no progress for 300 steps.*creep'):
            opt.run(fmax=1e-3, steps=5000)
    assert opt.nsteps < 5000 and np.isfinite(atoms.positions).all()


# -- the run monitor ------------------------------------------------------------

def _grow(monitor, x, forces_at, steps=200, factor=1.15):
    """Check ``monitor`` along a run that scales ``x`` by ``factor`` a step
    (shifting it too), the forces at each point ``forces_at(y)``."""
    for step in range(steps):
        y = x * factor**step + step
        monitor.check(step, y, 0.0, forces_at(y), 1.0, 1.0, 1e-12)


@pytest.mark.parametrize('seed', [0, 1])
def test_monitor_stops_a_run_no_force_slows(seed):
    # A constant push, as on a free scene under a load: no curvature along
    # the move, no balance anywhere: diverged, named a spread or a drift.
    x = np.random.default_rng(seed).uniform(-1, 1, (10, 3))
    push = np.random.default_rng(seed + 10).normal(size=(10, 3))
    monitor = RunMonitor(divergence_factor=2.0, patience=1000)
    with pytest.raises(DivergenceError, match='drifted by|spread to') as error:
        _grow(monitor, x, lambda y: push)
    assert 'no nearer' in str(error.value)
    unbounded = RunMonitor(divergence_factor=np.inf, patience=1000)
    _grow(unbounded, x, lambda y: push)   # switched off


@pytest.mark.parametrize('seed', [0, 1])
def test_monitor_lets_a_spring_held_run_grow(seed):
    # Zero-length springs to far anchors (equilibrium far out): the secant
    # curvature along the move sees them, so the growth is no divergence.
    rng = np.random.default_rng(seed)
    x = rng.uniform(-1, 1, (10, 3))
    far = x * 1.15**60 + 60 + rng.normal(size=(10, 3))
    monitor = RunMonitor(divergence_factor=2.0, patience=1000)
    _grow(monitor, x, lambda y: 1e-3 * (far - y), steps=60)
    assert monitor.marks >= 5 and monitor.passes == 0
    bounded = RunMonitor(divergence_factor=2.0, patience=1000, bounded=True)
    _grow(bounded, x, lambda y: np.ones_like(y))   # proved: never diverged
    assert bounded.marks == 0


@pytest.mark.parametrize('seed', range(3))
def test_measures_are_numpys(seed):
    # the centroid, the largest distance from it and the largest force, to
    # the last digit of numpy's formulas, at any scale; a NaN is the result's
    rng = np.random.default_rng(seed)
    for n in (1, 2, int(rng.integers(3, 400))):
        x = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-8, 8) + rng.normal(size=3)
        forces = rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-8, 8)
        centre, size, fmax = measures(x, forces)
        assert (centre == x.sum(axis=0) / n).all()
        assert size == np.linalg.norm(x - centre, axis=1).max()
        assert fmax == np.linalg.norm(forces, axis=1).max()
        x[rng.integers(n), rng.integers(3)] = np.nan
        assert np.isnan(measures(x, forces)[1]) and np.isnan(measures(forces, x)[2])


def test_monitor_names_stagnation_and_an_underflowed_gamma():
    monitor = RunMonitor(divergence_factor=3.0, patience=5)
    x = np.zeros((2, 3))
    x[1, 0] = 1.0
    forces = np.ones((2, 3))
    for step in range(6):
        monitor.check(step, x, 1.0, forces, 1.0, 1.0, 1e-12)
    with pytest.raises(StagnationError, match='no progress for 5 steps'):
        monitor.check(6, x, 1.0, forces, 1.0, 1.0, 1e-12)
    fresh = RunMonitor(divergence_factor=3.0, patience=5)
    with pytest.raises(StagnationError, match='gamma fell to 1e-13.*raised the energy'):
        fresh.check(0, x, 1.0, forces, 1e-13, 1.0, 1e-12)
    # a band of images: its steps are judged by its forces' work, and say so
    band = RunMonitor(divergence_factor=np.inf, patience=5, merit_name='|f|^2', band=True)
    with pytest.raises(StagnationError, match="overshot \\(the band's forces did negative"):
        band.check(0, x, 1.0, forces, 1e-13, 1.0, 1e-12)


def test_monitor_state_counts_steps_from_the_restart():
    monitor = RunMonitor(divergence_factor=3.0, patience=5)
    x = np.zeros((2, 3))
    x[1, 0] = 1.0
    monitor.check(7, x, 2.0, np.ones((2, 3)), 1.0, 1.0, 1e-12)
    resumed = RunMonitor(divergence_factor=3.0, patience=5)
    resumed.load(monitor.todict(step=7))
    assert resumed.best == (monitor.best[0], 0) and resumed.lowest == (2.0, 0)
    assert resumed.size0 == monitor.size0


@pytest.mark.parametrize('seed', range(4))
def test_monitor_catches_a_creep_at_any_scale(seed):
    """An energy that keeps falling, but by less than ENERGY_PROGRESS fmax
    times the scene's size over ``patience`` steps, with fmax stuck, is a
    stagnation at every scale of energy and length; one falling faster is
    progress."""
    rng = np.random.default_rng(seed)
    energy, length, patience = 10.0 ** rng.uniform(-8, 16), 10.0 ** rng.uniform(-8, 8), 20
    x = length * rng.uniform(-1, 1, (5, 3))
    size = np.linalg.norm(x - x.mean(axis=0), axis=1).max()
    forces = np.full((5, 3), energy / length)
    fmax = np.linalg.norm(forces, axis=1).max()

    def run(fall):
        monitor = RunMonitor(divergence_factor=3.0, patience=patience)
        merit = 100.0 * energy
        for step in range(3 * patience):
            monitor.check(step, x, merit, forces, 1.0, 1.0, 1e-16 * abs(merit))
            merit -= fall * fmax * size / patience
        return monitor

    with pytest.raises(StagnationError, match='creep'):
        run(fall=0.5 * ENERGY_PROGRESS)
    assert run(fall=5 * ENERGY_PROGRESS).lowest[1] > 2 * patience
