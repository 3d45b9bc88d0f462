"""Maud's run arguments and keywords: checked by name where they enter.

The property test draws hostile run arguments, keyword values and scales
(``a``, ``Q`` from 1e-12 to 1e12) and asserts a correct answer (the minimum
BFGS finds from the same start, scaled) or a ValueError/MaudError with a
message: never a non-finite position, never a raw TypeError, never a result
the calculator would not give afresh. Threads: run pinned (see
docs/hard_cases.md); the assertions do not depend on rounding."""

import inspect
import os
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from ase_maud import Maud, MaudCalculator, MaudError
from ase_maud.checks import RULES
from ase_maud.scenes.catalogue import build

from helpers import bfgs_reference

EXAMPLES = int(os.environ.get('ASE_MAUD_EXAMPLES', 200))

#: Hostile values: wrong types, non-finite, zero, signs, extremes.
HOSTILE = st.one_of(
    st.none(), st.booleans(), st.text(max_size=3), st.just([1.0]), st.just({}),
    st.sampled_from([np.nan, np.inf, -np.inf, 0.0, -0.0, -1.0, 1e-300, 1e300,
                     0.5, 1.0, 2.0, 10**400, np.float32(0.3), np.int64(7)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-10, 10**6))

#: Maud's numeric keywords (and those of run), with their rules in RULES.
NUMERIC = [name for name in [*inspect.signature(Maud).parameters, 'fmax', 'steps']
           if name in RULES and not RULES[name].choices]

#: Maud's keywords beyond the numeric ones (the last value of each is
#: refused).
NAMED = {'model': ['auto', 'exact', 'global', 'springs', 'nodal', 'secant', 'fast'],
         'method': ['tensor', 'scalar', 'vector'],
         'target': ['minimum', 'stationary', 'max']}

#: Values each keyword accepts, drawn as often as hostile ones.
VALID = {
    'gamma': st.floats(0.05, 2.0), 'gamma_max': st.none() | st.floats(0.5, 2.0),
    'gamma_growth': st.floats(1.0, 3.0), 'overshoot_shrink': st.floats(0.05, 1.0),
    'beta_max': st.none() | st.floats(0.0, 0.99), 'memory': st.none() | st.integers(0, 40),
    'floor': st.none() | st.floats(1e-12, 0.5), 'maxstep_nn': st.floats(0.01, 0.49),
    'maxstep': st.none() | st.floats(1e-3, 1e3), 'kappa0': st.floats(1e-6, 1e6),
    'divergence_factor': st.floats(1.5, 1e3), 'patience': st.integers(20, 5000),
    **{name: st.sampled_from(values[:-1]) for name, values in NAMED.items()}}


def mostly(valid, hostile=HOSTILE, share=3):
    """``valid`` values ``share`` times as often as ``hostile`` ones."""
    return st.integers(0, share).flatmap(lambda k: valid if k else hostile)


KEYWORD_VALUES = st.sampled_from(sorted(VALID)).flatmap(
    lambda name: st.tuples(st.just(name), mostly(VALID[name], share=1)))


# -- 1. run arguments and keywords ---------------------------------------------------

@pytest.mark.parametrize('call', ['run', 'irun'])
@pytest.mark.parametrize('fmax, steps, bad', [
    (-1, 10, 'fmax'), (np.nan, 10, 'fmax'), (np.inf, 10, 'fmax'),
    (None, 10, 'fmax'), ('x', 10, 'fmax'), (True, 10, 'fmax'), ([0.1], 10, 'fmax'),
    (0.1, -1, 'steps'), (0.1, np.nan, 'steps'), (0.1, 1.5, 'steps'),
    (0.1, 'x', 'steps'), (0.1, None, 'steps'), (0.1, True, 'steps'),
    (0.1, np.inf, 'steps')])
def test_bad_run_arguments_are_refused(call, fmax, steps, bad):
    atoms = build('ring', 8, seed=1)
    start = atoms.positions.copy()
    accepted = {'fmax': r'a finite number >= 0', 'steps': 'a whole number >= 0'}[bad]
    with Maud(atoms, logfile=None) as opt, pytest.raises(
            ValueError, match=f'^{bad} must be {accepted}.*got {re.escape(repr(locals()[bad]))}'):
        getattr(opt, call)(fmax=fmax, steps=steps)
    assert np.array_equal(atoms.positions, start)


@pytest.mark.parametrize('steps', [0, 2, 2.0, np.int64(2), 3e0])
def test_whole_steps_are_accepted(steps):
    with Maud(build('ring', 8, seed=1), logfile=None) as opt:
        assert not opt.run(fmax=1e-12, steps=steps)
    assert opt.nsteps == int(steps)


BAD_KEYWORDS = [(name, value) for name in sorted(NUMERIC) if name not in ('fmax', 'steps')
                for value in (np.nan, np.inf, -np.inf, '1', True, [1], -1.0)
                if (name, value) != ('divergence_factor', np.inf)   # no test: allowed
                ] + [(name, None) for name in ('gamma', 'overshoot_shrink', 'kappa0',
                                               'divergence_factor', 'patience')
                     ] + [('memory', 1.5), ('patience', 2.5), ('maxstep_nn', 0.5),
                          ('beta_max', 1.0), ('gamma_growth', 0.9),
                          ('divergence_factor', 1.0), ('floor', 1.0)
                          ] + [(name, value) for name, values in NAMED.items()
                               for value in (values[-1], 3, ['auto'])
                               ] + [('model', None), ('method', None)]


@pytest.mark.parametrize('name, value', BAD_KEYWORDS)
def test_bad_keywords_are_refused_by_name(name, value):
    with pytest.raises(ValueError, match=f'^{name} must be .*got {re.escape(repr(value))}'):
        Maud(build('ring', 8, seed=1), logfile=None, **{name: value})


@pytest.mark.parametrize('name, value, match', [
    ('logfile', 1, "logfile must be None, a file name, an open file, '-'"),
    ('logfile', True, 'logfile must be None'),
    ('trajectory', 3.5, 'trajectory must be None, a file name, an open file'),
    ('restart', object(), 'restart must be None, a file name, got'),
    ('trajectory', 'missing/maud.traj', "directory 'missing' does not exist"),
    ('logfile', 'missing/maud.log', "directory 'missing' does not exist"),
    ('restart', 'missing/maud.json', "directory 'missing' does not exist"),
    ('restart', '.', "restart '.' is a directory"),
    ('trajectory', '', "trajectory '' is a directory"),
    ('append_trajectory', 'yes', 'append_trajectory must be True or False'),
])
def test_bad_file_arguments_are_refused(tmp_path, monkeypatch, name, value, match):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=re.escape(match) if '(' in match else match):
        Maud(build('ring', 8, seed=1), **{'logfile': None, name: value})


@pytest.mark.slow   # 7 s
@settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2), scale=st.tuples(st.floats(-12, 12), st.floats(-12, 12)),
       fmax=mostly(st.floats(1e-9, 1e-5)), steps=mostly(st.integers(0, 400)),
       keyword_value=KEYWORD_VALUES)
def test_hostile_inputs_get_an_answer_or_a_clear_error(seed, scale, fmax, steps,
                                                       keyword_value):
    keyword, value = keyword_value
    a, q = 10.0 ** scale[0], 10.0 ** scale[1]
    atoms = build('hanging_net', 4, seed=seed, a=a, Q=q)
    relative = isinstance(fmax, float) and 1e-9 <= fmax <= 1e-5
    fmax = fmax * q * a if relative else fmax   # a relative fmax, or hostile
    try:
        with Maud(atoms, logfile=None, **{keyword: value}) as opt:
            converged = opt.run(fmax=fmax, steps=steps)
    except ValueError as error:
        name = str(error).split()[0]
        assert name in (keyword, 'fmax', 'steps', 'model=' + repr(value)), error
        assert 'must be' in str(error) or 'needs' in str(error), error
        event(f'ValueError: {name.split("=")[0]}')
    except MaudError as error:
        assert str(error), 'a MaudError without a message'
        event(f'MaudError: {type(error).__name__}')
    else:
        forces = atoms.get_forces()
        largest = np.linalg.norm(forces, axis=1).max()
        assert converged == (largest < fmax), (converged, largest, fmax)
        if converged and relative:   # (a huge fmax is met anywhere)
            energy, distances = bfgs_reference(seed)
            assert atoms.get_potential_energy() / (q * a**2) == pytest.approx(
                energy, rel=1e-8)
            gap = np.sort(atoms.get_all_distances(), axis=None) / a - distances
            assert np.abs(gap).max() < 1e-4
        event(('converged to the minimum' if relative else 'converged (huge fmax)')
              if converged else 'not converged within steps')
    assert np.isfinite(atoms.positions).all()
    # Never stale: a fresh calculator agrees with what the atoms hold.
    fresh = MaudCalculator(**atoms.calc.parameters)
    assert atoms.get_potential_energy() == pytest.approx(
        fresh.get_potential_energy(atoms.copy()), rel=1e-12, abs=0)
