"""The compiled step (ase_maud.optimize.compiled_step) makes the exact model's Python
step: the same steps and calculator calls, the same energies and end points to
round-off, on fresh seeded scenes; the calculator holds each of its evaluations."""

import numpy as np
import pytest
from ase.constraints import FixAtoms, FixCartesian

from ase_maud import Maud
from ase_maud.calculator.compiled_sums import scene_terms
from ase_maud.counting import CallRecorder, fresh_copy
from ase_maud.optimize import compiled_step
from ase_maud.scenes.catalogue import build

#: (scene, size, build keywords): clusters in 3D and 2D, held nets under
#: loads, a net without repulsion (quadratic), a wheel, a random graph.
SCENES = [('all_pairs', 10, {}), ('all_pairs2d', 12, {}), ('hanging_net', 5, {}),
          ('weighted_net', 4, {}), ('net2d', 4, {'a': 0.0}), ('wheel', 10, {}),
          ('random_graph', 14, {})]


def _scene(name, size, keywords, seed):
    atoms = build(name, size, seed=seed, **keywords)
    if name == 'all_pairs':   # a held point and a held coordinate too
        atoms.set_constraint([FixAtoms([0]), FixCartesian(1, [False, True, False])])
    atoms.rattle(0.05, seed=seed)
    if atoms.calc.dim == 2:
        atoms.positions[:, 2] = 0.0
    return atoms


def _run(atoms, compiled, monkeypatch, fmax=1e-7, steps=300):
    """A run on arrays by the compiled step or the Python step: the optimizer,
    whether it converged, and each calculator call's (fmax, energy)."""
    taken = []
    relax = compiled_step.relax
    with monkeypatch.context() as patch:
        if compiled:
            patch.setattr(compiled_step, 'relax', lambda *a: taken.append(1) or relax(*a))
        else:
            patch.setattr(compiled_step, 'applies', lambda *a: False)
        with CallRecorder(atoms.calc) as recorder:
            with Maud(atoms, logfile=None) as opt:
                converged = opt.run(fmax=fmax, steps=steps)
    assert bool(taken) == compiled
    return opt, converged, np.array([sample[3:] for sample in recorder.samples])


@pytest.mark.parametrize('scene', SCENES, ids=lambda s: f'{s[0]}:{s[1]}')
@pytest.mark.parametrize('seed', [31, 32])
def test_the_compiled_step_makes_the_python_step_s_moves(scene, seed, monkeypatch):
    name, size, keywords = scene
    ends = []
    for compiled in (True, False):
        atoms = _scene(name, size, keywords, seed)
        ends.append((atoms, *_run(atoms, compiled, monkeypatch)))
    (atoms, opt, converged, calls), (python, python_opt, python_converged, python_calls) = ends
    assert converged and python_converged
    assert opt.nsteps == python_opt.nsteps and len(calls) == len(python_calls)
    # the compiled pass gives a Hessian with every evaluation, the last too;
    # the Python step asks a held net's block only where a step starts
    assert opt.work.hessians - python_opt.work.hessians in (0, 1)
    scale = np.abs(python_calls[:, 1]).max()
    np.testing.assert_allclose(calls[:, 1], python_calls[:, 1], rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(calls[:, 0], python_calls[:, 0], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(atoms.positions, python.positions, rtol=0, atol=1e-6)
    assert (opt.state.gamma, opt.state.k) == (python_opt.state.gamma, python_opt.state.k)


@pytest.mark.parametrize('seed', [33, 34])
def test_a_run_carried_on_by_the_python_step_ends_where_one_compiled_run_ends(
        seed, monkeypatch):
    """The compiled step leaves the optimizer's state (gamma, steps since a
    restart, the last point) as the Python step does: a second ``run`` on the
    same optimizer (the Python step: the state is no longer fresh) carries
    on the first run's steps as one run makes them."""
    whole = _scene('all_pairs', 12, {}, seed)
    with Maud(whole, logfile=None) as opt:
        opt.run(fmax=1e-300, steps=12)
    split = _scene('all_pairs', 12, {}, seed)
    with Maud(split, logfile=None) as opt:
        opt.run(fmax=1e-300, steps=5)
        assert not compiled_step.applies(opt.strategy, opt.state, split)
        opt.run(fmax=1e-300, steps=7)
    np.testing.assert_allclose(split.positions, whole.positions, rtol=0, atol=1e-8)


@pytest.mark.parametrize('seed', [35, 36])
def test_the_calculator_holds_each_evaluation_of_the_compiled_step(seed):
    atoms = _scene('hanging_net', 5, {}, seed)
    with CallRecorder(atoms.calc) as recorder:
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-4, steps=6)
        calls = len(recorder.samples)
        energy, forces = atoms.get_potential_energy(), atoms.get_forces()
        assert len(recorder.samples) == calls   # the results held are the last positions'
    assert calls == opt.nsteps + 1
    fresh = fresh_copy(atoms)
    assert energy == pytest.approx(fresh.get_potential_energy(), rel=1e-12)
    np.testing.assert_allclose(forces, fresh.get_forces(), rtol=0, atol=1e-10)
    assert atoms.calc.last_backend == 'numba' and atoms.calc.last_tolerance == 0.0


@pytest.mark.parametrize('scene', [('all_pairs', 9, {}), ('all_pairs2d', 8, {}),
                                   ('weighted_net', 4, {}), ('net2d', 4, {'a': 0.0})],
                         ids=lambda s: f'{s[0]}:{s[1]}')
@pytest.mark.parametrize('seed', [37, 38])
def test_scene_terms_are_the_calculator_s_energy_forces_and_hessian(scene, seed):
    name, size, keywords = scene
    atoms = _scene(name, size, keywords, seed)
    rng = np.random.default_rng(seed)
    atoms.calc.set(q=rng.uniform(0.5, 2.0, len(atoms.calc.springs)))
    law = atoms.calc.potential.scene_arrays(len(atoms))
    energy, forces, hessian, _ = scene_terms(atoms.positions.copy(), law)
    atoms.calc.compute(atoms, ['hessian'])
    results = atoms.calc.results
    assert energy == pytest.approx(results['energy'], rel=1e-14, abs=1e-14)
    np.testing.assert_allclose(forces, results['forces'], rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(hessian, results['hessian'], rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize('keywords, why', [
    ({'model': 'springs'}, 'another model'),
    ({'beta_max': 0.5}, 'momentum'),
    ({'memory': 5}, 'a memory'),
    ({'target': 'stationary'}, 'another target'),
])
def test_other_runs_keep_the_python_step(keywords, why):
    atoms = build('all_pairs', 8, seed=39)
    assert compiled_step.applies(Maud(atoms, logfile=None).strategy,
                                 Maud(atoms, logfile=None).state, atoms)
    opt = Maud(atoms, logfile=None, **keywords)
    assert not compiled_step.applies(opt.strategy, opt.state, atoms), why
    numpy_sums = build('all_pairs', 8, seed=39)
    numpy_sums.calc.set(backend='numpy')
    opt = Maud(numpy_sums, logfile=None)
    assert not compiled_step.applies(opt.strategy, opt.state, numpy_sums)


def test_a_subclass_of_the_calculator_keeps_the_python_step():
    """A MaudCalculator subclass may compute its results otherwise (noise, a
    correction): the compiled pass, which makes MaudCalculator's own, does
    not stand in for it."""
    from ase_maud import MaudCalculator

    class Shifted(MaudCalculator):
        def calculate(self, *args, **kwargs):
            super().calculate(*args, **kwargs)
            self.results['energy'] += 1.0

    atoms = build('all_pairs', 8, seed=44)
    atoms.calc = Shifted(**atoms.calc.parameters)
    opt = Maud(atoms, logfile=None)
    assert not compiled_step.applies(opt.strategy, opt.state, atoms)
    opt.run(fmax=1e-6)
    plain = atoms.copy()
    plain.calc = MaudCalculator(**atoms.calc.parameters)
    assert atoms.get_potential_energy() == pytest.approx(
        plain.get_potential_energy() + 1.0, rel=1e-12)


@pytest.mark.parametrize('seed', [40, 41])
def test_a_non_finite_pass_is_the_calculator_s_to_judge(seed, monkeypatch):
    """Where the compiled pass gives a non-finite result the calculator
    computes the positions itself (and raises if it finds them bad): the run
    goes on with its results."""
    start = _scene('wheel', 8, {}, seed)
    reference = start.copy()
    reference.calc = fresh_copy(start).calc
    with Maud(reference, logfile=None) as opt:
        opt.run(fmax=1e-6)
    passes = []
    terms = compiled_step.scene_terms

    def second_fails(x, law):
        energy, *rest = terms(x, law)
        passes.append(1)
        return (np.nan if len(passes) == 2 else energy), *rest

    monkeypatch.setattr(compiled_step, 'scene_terms', second_fails)
    with Maud(start, logfile=None) as opt:
        opt.run(fmax=1e-6)
    assert len(passes) > 2
    np.testing.assert_allclose(start.positions, reference.positions, rtol=0, atol=1e-8)


@pytest.mark.parametrize('seed', [44, 45])
def test_a_non_finite_move_stops_the_run_where_it_was(seed, monkeypatch):
    """A move with a NaN stops the run with a MaudError that says so; the
    points stay where the last evaluation was, held ones too."""
    from ase_maud.errors import MaudError
    atoms = _scene('hanging_net', 5, {}, seed)
    moves, kept = [], []
    move = compiled_step._move

    def third_fails(*args):
        moves.append(move(*args))
        kept.append(atoms.positions.copy())
        return moves[-1] * np.nan if len(moves) == 3 else moves[-1]

    monkeypatch.setattr(compiled_step, '_move', third_fails)
    with Maud(atoms, logfile=None) as opt:
        with pytest.raises(MaudError, match='no finite step from step 2.*non-finite move'):
            opt.run(fmax=1e-8)
    assert len(moves) == 3 and np.isfinite(atoms.positions).all()
    np.testing.assert_array_equal(atoms.positions, kept[-1])


@pytest.mark.parametrize('seed', [42, 43])
def test_a_large_held_net_keeps_the_python_step_s_block_of_the_hessian(seed):
    """Where most points are held the exact model asks for the Hessian's block
    on the free ones; above EXACT_MAX_DOFS coordinates the compiled step
    (which forms the whole) leaves such a scene to the Python step."""
    from ase_maud.optimize.models.exact import EXACT_MAX_DOFS
    net = build('hanging_net', 9, seed=seed)
    held = [i for i in range(len(net)) if i % 9 not in (3, 4, 5)]
    net.set_constraint(FixAtoms(held))
    assert 3 * len(net) > EXACT_MAX_DOFS
    opt = Maud(net, logfile=None, model='exact')
    assert opt.model.needs(net) is None   # the block
    assert not compiled_step.applies(opt.strategy, opt.state, net)
    small = build('hanging_net', 5, seed=seed)
    opt = Maud(small, logfile=None, model='exact')
    assert opt.model.needs(small) is None and compiled_step.applies(opt.strategy, opt.state,
                                                                    small)
