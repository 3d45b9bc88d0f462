"""A run on arrays (ase_maud.optimize.array_loop) makes the steps ASE's loop makes, bit for
bit by the Python step and to round-off by the compiled one; and a run leaves the
calculator's settings as the user set them."""

import io

import numpy as np
import pytest
from ase.constraints import FixAtoms, FixCartesian

from ase_maud import Maud
from ase_maud.counting import CallRecorder
from ase_maud.scenes.catalogue import build

SCENES = [('all_pairs', 12), ('hanging_net', 5), ('tree', 20), ('all_pairs2d', 14),
          ('wheel', 12)]


def _steps_of_log(log):
    """The log without its clock column (the time of day of each step)."""
    return [line[:10] + line[19:] for line in log.getvalue().splitlines()]


@pytest.mark.parametrize('compiled', [False, True])
@pytest.mark.parametrize('scene', SCENES, ids=lambda s: f'{s[0]}:{s[1]}')
@pytest.mark.parametrize('seed', [11, 12])
def test_a_run_on_arrays_is_the_watched_run(scene, seed, compiled, monkeypatch):
    """Without an observer Maud runs on arrays; with one (a no-op callback)
    through ASE's loop: the step count, log and number of calculator calls
    are the same, and the positions and energy bit for bit by the Python
    step, to round-off by the compiled one (these scenes' exact model:
    :mod:`ase_maud.optimize.compiled_step`)."""
    from ase_maud.optimize import compiled_step
    if not compiled:
        monkeypatch.setattr(compiled_step, 'applies', lambda *args: False)
    name, size = scene
    runs = []
    for watched in (False, True):
        atoms = build(name, size, seed=seed)
        if name == 'all_pairs':   # a held point and a held coordinate too
            atoms.set_constraint([FixAtoms([0]), FixCartesian(1, [False, True, False])])
        log = io.StringIO()
        with CallRecorder(atoms.calc) as recorder:
            with Maud(atoms, logfile=log) as opt:
                if watched:
                    opt.attach(lambda: None)
                converged = opt.run(fmax=1e-7, steps=400)
        runs.append((atoms, opt, converged, _steps_of_log(log), len(recorder.samples)))
    (quiet, fast, done, quiet_log, quiet_calls), (watched, slow, also, log, calls) = runs
    assert done and also
    assert fast.nsteps == slow.nsteps and quiet_calls == calls == fast.nsteps + 1
    assert quiet_log == log
    if compiled:
        np.testing.assert_allclose(quiet.positions, watched.positions, rtol=0, atol=1e-7)
        assert quiet.get_potential_energy() == pytest.approx(watched.get_potential_energy(),
                                                             rel=1e-12)
    else:
        np.testing.assert_array_equal(quiet.positions, watched.positions)
        assert quiet.get_potential_energy() == watched.get_potential_energy()


@pytest.mark.parametrize('model', ['springs', 'global', 'nodal', 'secant', 'bfgs'])
@pytest.mark.parametrize('scene', [('hanging_net', 8), ('all_pairs', 12), ('tree', 20)],
                         ids=lambda s: f'{s[0]}:{s[1]}')
@pytest.mark.parametrize('seed', [11, 12])
def test_every_model_runs_on_arrays_as_in_the_watched_run(model, scene, seed):
    """Each model seeking a minimum makes the same steps on arrays as in ASE's
    loop: positions, energy, steps, calculator calls (none where a step
    moves nothing, none for a model kept) and log, converged or stopped at
    ``steps``."""
    name, size = scene
    runs = []
    for watched in (False, True):
        atoms = build(name, size, seed=seed)
        if name == 'tree':   # a held point
            atoms.set_constraint(FixAtoms([0]))
        log = io.StringIO()
        with CallRecorder(atoms.calc) as recorder:
            with Maud(atoms, logfile=log, model=model) as opt:
                if watched:
                    opt.attach(lambda: None)
                converged = opt.run(fmax=1e-6, steps=150)
        runs.append((atoms, opt.nsteps, converged, _steps_of_log(log), len(recorder.samples)))
    (quiet, steps, done, quiet_log, quiet_calls), (watched, *rest) = runs
    assert [steps, done, quiet_log, quiet_calls] == rest
    assert steps > 0
    np.testing.assert_array_equal(quiet.positions, watched.positions)
    assert quiet.get_potential_energy() == watched.get_potential_energy()


def test_a_run_on_arrays_keeps_held_coordinates_and_stops_at_steps():
    atoms = build('all_pairs', 16, seed=13)
    start = atoms.positions.copy()
    atoms.set_constraint([FixAtoms([2, 5]), FixCartesian(7, [True, False, True])])
    with Maud(atoms, logfile=None) as opt:
        assert not opt.run(fmax=1e-12, steps=3)
    assert opt.nsteps == 3
    np.testing.assert_array_equal(atoms.positions[[2, 5]], start[[2, 5]])
    np.testing.assert_array_equal(atoms.positions[7, [0, 2]], start[7, [0, 2]])
    assert np.abs(atoms.positions - start).max() > 1e-3
    # the calculator holds the results of the positions the run ended at
    fresh = atoms.copy()
    fresh.calc = type(atoms.calc)(**atoms.calc.parameters)
    np.testing.assert_allclose(atoms.get_forces(), fresh.get_forces(), rtol=1e-12,
                               atol=1e-12)


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('watched', [False, True])
def test_a_run_leaves_the_calculators_tolerance_as_the_user_set_it(seed, watched):
    """The run asks the calculator for coarser sums far from the answer
    (``ase_maud.calculator.accuracy.ask``); the user's ``tol`` is back when it ends, so a
    trajectory's or a later run's calculator parameters are the user's."""
    atoms = build('hanging_net', 30, seed=seed)   # the springs model
    atoms.calc.set(tol=1e-7)
    asked = []
    set_tolerance = atoms.calc.set_tolerance

    def recorded(tol):
        asked.append(tol)
        set_tolerance(tol)

    atoms.calc.set_tolerance = recorded
    with Maud(atoms, logfile=None) as opt:
        if watched:
            opt.attach(lambda: None)
        opt.run(fmax=1e-3, steps=30)
    assert any(tol != 1e-7 for tol in asked[:-1])   # the run asked for others
    assert atoms.calc.parameters['tol'] == 1e-7
    assert atoms.calc.todict()['tol'] == 1e-7


def test_a_run_on_arrays_counts_its_hessians_as_the_watched_run():
    counts = []
    for watched in (False, True):
        atoms = build('all_pairs', 10, seed=21)
        with Maud(atoms, logfile=None) as opt:
            if watched:
                opt.attach(lambda: None)
            opt.run(fmax=1e-7)
        counts.append((opt.nsteps, opt.work.hessians))
    assert counts[0] == counts[1] and counts[0][1] == counts[0][0] + 1


@pytest.mark.parametrize('loop', ['watched', 'arrays', 'compiled'])
@pytest.mark.parametrize('seed', [0, 1])
def test_a_run_with_no_finite_step_says_so_once_in_its_log(seed, loop, monkeypatch):
    """A local model that fails (here: the exact model's factorisation) stops
    the run with one line in the log, on arrays (by the Python or the compiled
    step) and in ASE's loop alike (the error passes the optimizer's stop twice
    on its way out)."""
    from ase_maud.errors import MaudError
    from ase_maud.optimize import compiled_step
    from ase_maud.optimize.models.exact import ExactModel

    def failing(*args):
        raise np.linalg.LinAlgError('no factor')

    monkeypatch.setattr(ExactModel, 'local', failing)
    if loop == 'compiled':   # these clusters are far from definite at their start
        monkeypatch.setattr(compiled_step, 'eigenpairs_of', failing)
    else:
        monkeypatch.setattr(compiled_step, 'applies', lambda *args: False)
    watched = loop == 'watched'
    atoms, log = build('all_pairs', 6 + seed, seed=seed), io.StringIO()
    opt = Maud(atoms, logfile=log)
    if watched:
        opt.attach(lambda: None)
    with pytest.raises(MaudError, match='no finite step from step 0') as error:
        opt.run(fmax=1e-6)
    assert log.getvalue().count('Maud: stopped:') == 1
    assert f'Maud: stopped: {error.value}' in log.getvalue()


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_step_that_moves_nothing_costs_no_call_on_arrays_either(seed, monkeypatch):
    """Every third step made a zero move (as a step cut to nothing would be):
    ASE's loop asks the calculator nothing there (the results held are of
    those positions), and neither does the run on arrays."""
    from ase_maud.optimize.strategy import Minimise

    step = Minimise.step

    def some_still(self, state, *args):
        move = step(self, state, *args)
        return move * 0.0 if state.k % 3 == 2 else move

    monkeypatch.setattr(Minimise, 'step', some_still)
    runs = []
    for watched in (False, True):
        atoms = build('hanging_net', 6, seed=seed)
        with CallRecorder(atoms.calc) as recorder:
            with Maud(atoms, logfile=None, model='springs', beta_max=0.5) as opt:
                if watched:
                    opt.attach(lambda: None)
                opt.run(fmax=1e-6, steps=30)
        runs.append((opt.nsteps, len(recorder.samples), atoms.positions.copy()))
    (steps, calls, quiet), (also, watched_calls, watched) = runs
    assert steps == also and calls == watched_calls < steps + 1
    np.testing.assert_array_equal(quiet, watched)


@pytest.mark.parametrize('seed', [3, 4])
def test_one_exact_model_follows_constraints_changed_between_runs_on_arrays(seed):
    """One exact model (it keeps its constraints' basis and free components)
    relaxes the same Atoms on arrays three times: then after its FixAtoms is
    changed in place, then after new constraints are set. The held
    coordinates never move and each run is, bit for bit, a fresh model's on
    a copy (on arrays and in ASE's loop)."""
    from ase_maud.optimize.models.exact import ExactModel
    rng = np.random.default_rng(seed)
    atoms = build('all_pairs', 12, seed=seed)
    fix = FixAtoms([0, 1])
    atoms.set_constraint(fix)
    kept = ExactModel()
    for change in range(3):
        if change == 1:
            fix.index = np.sort(rng.choice(len(atoms), 3, replace=False))
        elif change == 2:
            atoms.set_constraint([FixAtoms([5]), FixCartesian(2, [True, False, True])])
        atoms.rattle(0.2, seed=seed + change)
        start = atoms.positions.copy()
        ends = []
        for watched in (False, True):
            run = atoms.copy()
            run.calc = atoms.calc
            with Maud(run, logfile=None, model=ExactModel()) as opt:
                if watched:
                    opt.attach(lambda: None)
                opt.run(fmax=1e-6, steps=300)
            ends.append(run.positions)
        with Maud(atoms, logfile=None, model=kept) as opt:   # the same Atoms and model
            opt.run(fmax=1e-6, steps=300)
        # on arrays by the compiled step; in ASE's loop by the Python one (to round-off)
        assert atoms.positions.tobytes() == ends[0].tobytes()
        np.testing.assert_allclose(ends[0], ends[1], rtol=0, atol=1e-7)
        for c in atoms.constraints:
            held = np.zeros((len(atoms), 3), dtype=bool)
            held[c.index] = True if isinstance(c, FixAtoms) else c.mask
            assert (atoms.positions[held] == start[held]).all()
        assert not (atoms.positions == start).all()
