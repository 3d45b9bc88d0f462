"""Nothing silently wrong: checked arguments, no non-finite value
reaching the user, the atomic restart file, planar scenes under ASE drivers.

The property test draws hostile run arguments, keyword values and scales
(``a``, ``Q`` from 1e-12 to 1e12) and asserts a correct answer (the minimum
BFGS finds from the same start, scaled) or a ValueError/MaudError with a
message: never a non-finite position, never a raw TypeError, never a result
the calculator would not give afresh. Threads: run pinned (see
docs/hard_cases.md); the assertions do not depend on rounding.
"""

import functools
import inspect
import json
import os
import re
import shutil

import numpy as np
import pytest
from ase.calculators.calculator import all_changes
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron
from ase.io import read
from ase.optimize import BFGS
from ase.optimize.basin import BasinHopping
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from ase_maud import Maud, MaudCalculator, MaudError
from ase_maud.bench.doubles import PoisonedCalculator
from ase_maud.bench.hard_inputs import DAMAGES
from ase_maud.checks import RULES
from ase_maud.files.trajectory import last_frame
from ase_maud.optimize.restart_file import RestartFile
from ase_maud.scenes.builders import keep_on_plane
from ase_maud.scenes.catalogue import SCENES, build

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


@functools.cache
def reference(seed):
    """BFGS's minimum of the small scene at a = Q = 1: energy, sorted pair
    distances."""
    atoms = build('hanging_net', 4, seed=seed)
    with BFGS(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-10, steps=5000)
    return atoms.get_potential_energy(), np.sort(atoms.get_all_distances(), axis=None)


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
            energy, distances = reference(seed)
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


# -- 2. non-finite results of any calculator (ase_maud.bench.doubles.PoisonedCalculator) ---------


def emt_cluster():
    atoms = Icosahedron('Cu', 2)
    atoms.rattle(0.05, seed=1)
    return atoms, EMT()


def maud_net():
    atoms = build('hanging_net', 5, seed=1)
    return atoms, MaudCalculator(**atoms.calc.parameters)


@pytest.mark.parametrize('scene', [emt_cluster, maud_net])
@pytest.mark.parametrize('what', ['energy', 'forces'])
@pytest.mark.parametrize('value', [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize('call', [1, 4])
def test_non_finite_results_stop_the_run_at_good_positions(tmp_path, scene, what, value,
                                                           call):
    atoms, inner = scene()
    atoms.calc = PoisonedCalculator(inner, call, what, value)
    traj = tmp_path / 'run.traj'
    start = atoms.positions.copy()
    step = call - 1   # one calculator call per step
    text = ('a non-finite energy' if what == 'energy'
            else rf'non-finite forces \(atom 6: \[{value}, 0, 0\]\)')
    where = ('the atoms are at their start positions' if step == 0
             else f'positions restored to step {step - 1}')
    with pytest.raises(MaudError, match=f'calculator returned {text}.* at step {step}; '
                                        f'{where}$'):
        with Maud(atoms, logfile=None, trajectory=traj) as opt:
            opt.run(fmax=1e-6)
    assert np.isfinite(atoms.positions).all()
    if step == 0:
        assert np.array_equal(atoms.positions, start)
        assert last_frame(traj) is None
    else:
        frames = read(traj, ':')
        assert len(frames) == step   # frames 0 .. step - 1, none of the bad step
        assert all(np.isfinite(f.get_potential_energy()) and np.isfinite(f.get_forces()).all()
                   for f in frames)
        assert np.array_equal(atoms.positions, frames[-1].positions)


class PoisonedHessian(MaudCalculator):
    """MaudCalculator whose third call returns a Hessian with a NaN."""

    calls = 0

    def calculate(self, atoms=None, properties=('energy',), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.calls += 1
        if self.calls == 3:
            self.results['hessian'][2, 3] = self.results['hessian'][3, 2] = np.nan


def test_non_finite_stiffness_stops_the_run():
    atoms = build('ring', 8, seed=2)
    atoms.calc = PoisonedHessian(**atoms.calc.parameters)
    with pytest.raises(MaudError, match=r'no finite step from step 2: the calculator '
                                        r'returned a non-finite hessian \(entry \[2, 3\]'):
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-8)
    assert np.isfinite(atoms.positions).all()


# -- 3. the restart file -------------------------------------------------------------

def test_restart_file_is_replaced_whole(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    atoms = build('hanging_net', 5, seed=1)
    seen, replaced = [], []
    real_replace = os.replace

    def checked_replace(source, destination):
        """At the moment of the swap: the new state is whole, in the same
        folder, and names rows of the arrays file that are written already;
        the old file (if any) is whole too."""
        assert os.path.dirname(os.path.abspath(source)) == str(tmp_path)
        new = json.loads(open(source).read())
        shutil.copy(source, 'check.json')
        shutil.copy('maud.json.arrays', 'check.json.arrays')
        assert RestartFile('check.json').read()['step'] == new['step']
        os.remove('check.json')
        os.remove('check.json.arrays')
        if os.path.exists(destination):
            json.loads(open(destination).read())
        replaced.append(destination)
        real_replace(source, destination)

    monkeypatch.setattr('ase_maud.files.atomic_replace.os.replace', checked_replace)
    with Maud(atoms, logfile=None, restart='maud.json') as opt:
        opt.attach(lambda: seen.append(sorted(os.listdir('.'))))
        opt.run(fmax=1e-6, steps=5)
    assert len(replaced) == opt.nsteps                     # one swap per step
    # (the observers run before the file is written: from the second step on)
    assert all(names == ['maud.json', 'maud.json.arrays'] for names in seen[2:])
    saved = RestartFile(tmp_path / 'maud.json').read()
    assert saved['step'] == opt.nsteps
    assert np.array_equal(saved['x'], atoms.positions)


def test_restart_positions_win_and_are_logged(tmp_path):
    restart, log = tmp_path / 'maud.json', tmp_path / 'maud.log'
    straight = build('hanging_net', 5, seed=1)
    with Maud(straight, logfile=None) as opt:
        opt.run(fmax=1e-9)
    atoms = build('hanging_net', 5, seed=1)
    with Maud(atoms, logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=6)
    moved = build('hanging_net', 5, seed=1)   # the start, not step 6
    with Maud(moved, logfile=log, restart=restart) as opt:
        assert np.array_equal(moved.positions, atoms.positions)
        opt.run(fmax=1e-9)
    assert 'the atoms moved to the positions of step 6' in log.read_text()
    assert np.abs(moved.positions - straight.positions).max() < 1e-12


def test_restart_of_another_scene_is_refused(tmp_path):
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 5, seed=1), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-6, steps=2)
    with pytest.raises(ValueError, match=r'of another scene: points 25 in it, 36 in the '
                                         'atoms given'):
        Maud(build('hanging_net', 6, seed=1), logfile=None, restart=restart)
    restart.write_text('{"method": {}}')
    with pytest.raises(ValueError, match='not written by this version of Maud'):
        Maud(build('hanging_net', 5, seed=1), logfile=None, restart=restart)


def test_resume_without_files_starts_afresh(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    atoms = build('ring', 8, seed=1)
    start = atoms.positions.copy()
    with Maud.resume(atoms, logfile=None) as opt:
        assert np.array_equal(atoms.positions, start)
        assert opt.run(fmax=1e-6)
    assert len(read('maud.traj', ':')) == opt.nsteps + 1


# -- 4. planar scenes under ASE's drivers ----------------------------------------------

@pytest.mark.parametrize('name', [n for n in SCENES if build(n).calc.parameters['dim'] == 2])
def test_planar_scenes_keep_z(name):
    atoms = build(name, seed=1)
    z = atoms.positions[:, 2].copy()
    atoms.set_positions(atoms.positions + np.random.default_rng(1).normal(size=(len(atoms), 3)))
    assert np.array_equal(atoms.positions[:, 2], z)
    assert len(atoms.constraints) == len(keep_on_plane(atoms).constraints)   # idempotent


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


def test_off_plane_error_says_what_to_add():
    atoms = build('ring', 8, seed=1)
    del atoms.constraints
    atoms.positions[2, 2] += 0.1
    with pytest.raises(ValueError, match=r'atom 2 has z = 0.1.*keep_on_plane\(atoms\)'):
        atoms.get_potential_energy()


# -- 5. errors that name the input ------------------------------------------------------

@pytest.mark.parametrize('args, keywords, match', [
    (('ring', 'x'), {}, r"ring needs an integer size >= 3, got 'x'"),
    (('ring', np.nan), {}, r'ring needs an integer size >= 3, got nan'),
    (('chain', None), {'seed': 'x'}, r"seed must be a whole number >= 0, got 'x'"),
    (('chain', None), {'seed': 1.5}, r'seed must be a whole number >= 0, got 1.5'),
    (('ring', 8), {'a': 'x'}, r"a must be a finite number >= 0 \(0: no repulsion, "
     r"the force-density method\), got 'x'"),
    (('ring', 8), {'b': 1}, r"build takes the keywords a and Q, got \['b'\]"),
    (('molecule', 'XYZ'), {}, r"molecule needs the name of a molecule of ase.collections.g2 "
                              r".*got 'XYZ'"),
    ((3,), {}, r'unknown scene 3; known: dimer'),
])
def test_scene_errors_name_the_input(args, keywords, match):
    with pytest.raises(ValueError, match=match):
        build(*args, **keywords)


@pytest.mark.parametrize('seed', [0, 1])
def test_a_second_run_sees_a_changed_calculator(seed):
    """Energy and forces held by the optimiser are not reused after the
    calculator changed between runs."""
    atoms = build('hanging_net', 5, seed=seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-6)
        atoms.calc.set(Q=2.0)                 # the old minimum is no longer one
        assert opt.run(fmax=1e-6)
    reference = build('hanging_net', 5, seed=seed)
    reference.calc.set(Q=2.0)
    BFGS(reference, logfile=None).run(fmax=1e-7, steps=2000)
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-9)


def test_rows_that_never_reached_the_disk_are_refused(tmp_path):
    atoms = build('hanging_net', 12, seed=2)     # the springs model: L-BFGS pairs too
    restart = tmp_path / 'maud.json'
    with Maud(atoms, logfile=None, restart=restart, model='springs') as opt:
        opt.run(fmax=1e-9, steps=6)
    assert RestartFile(restart).read()['step'] == 6
    arrays = tmp_path / 'maud.json.arrays'
    data = bytearray(arrays.read_bytes())
    data[-8:] = bytes(range(1, 9))                # the last pair's last number
    arrays.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="rows .* of '.*maud.json.arrays' are not what it "
                                         'wrote'):
        Maud(build('hanging_net', 12, seed=2), logfile=None, restart=restart)


@pytest.mark.parametrize('sync_seconds,flushes', [(0.0, 'every step'), (1e9, 'none')])
@pytest.mark.parametrize('seed', [4, 9])
def test_restart_files_reach_the_disk_on_the_schedule(tmp_path, monkeypatch, seed,
                                                      sync_seconds, flushes):
    # both files flushed at each write when SYNC_SECONDS has passed; never
    # within it, not even at the first step
    from ase_maud.optimize import restart_file as restart_module
    monkeypatch.setattr(restart_module, 'SYNC_SECONDS', sync_seconds)
    synced = []
    real_fsync = os.fsync
    monkeypatch.setattr(os, 'fsync', lambda fd: (synced.append(fd), real_fsync(fd)))
    steps = int(np.random.default_rng(seed).integers(3, 8))
    with Maud(build('hanging_net', 6, seed=seed), logfile=None,
              restart=tmp_path / 'maud.json', model='springs') as opt:
        opt.run(fmax=1e-12, steps=steps)
    assert opt.nsteps == steps
    writes = opt.nsteps if flushes == 'every step' else 0   # one write per step
    assert len(synced) == 2 * writes


@pytest.mark.parametrize('seed', [3, 8])
def test_files_of_another_scene_with_as_many_points_are_refused(tmp_path, seed):
    # a ring's run resumed onto a net of as many points:
    # other springs, then the same springs with another a, or other fixed points
    ring = build('ring', 25, seed=seed)
    restart, trajectory = tmp_path / 'maud.json', tmp_path / 'maud.traj'
    with Maud(ring, logfile=None, restart=restart, trajectory=trajectory) as opt:
        opt.run(fmax=1e-6, steps=3)
    net = build('hanging_net', 5, seed=seed)
    with pytest.raises(ValueError, match=r"restart file .* of another scene: fixed points "
                                         r'0 in it, \d+ in the atoms given'):
        Maud(net, logfile=None, restart=restart)
    with pytest.raises(ValueError, match=r"trajectory .* of another scene: fixed points"):
        Maud.resume(net, restart=restart, trajectory=trajectory, logfile=None)
    net.set_constraint()
    with pytest.raises(ValueError, match=r'of another scene: its springs are other ones '
                                         r'\(as many: 25\)|springs 25 in it'):
        Maud(net, logfile=None, restart=restart)
    wider = build('ring', 25, seed=seed)
    wider.calc.set(a=2.0)
    for resume in (lambda: Maud(wider, logfile=None, restart=restart),
                   lambda: Maud.resume(wider, restart=restart, trajectory=trajectory,
                                       logfile=None)):
        with pytest.raises(ValueError, match=r'of another scene: a 1\.0 in it, 2\.0 in the '
                                             'atoms given'):
            resume()
    same = build('ring', 25, seed=seed)
    with Maud.resume(same, restart=restart, trajectory=trajectory, logfile=None) as opt:
        assert opt.run(fmax=1e-6)


@pytest.mark.parametrize('seed', [0, 4])
def test_loads_and_force_densities_are_part_of_the_scene(tmp_path, seed):
    # a loaded net with force densities resumed from its files: the same
    # steps as the run never stopped; other loads or other q are refused
    def scene():
        atoms = build('weighted_net', 6, seed=seed)
        rng = np.random.default_rng(seed)
        atoms.calc.set(q=rng.uniform(0.5, 2.0, len(atoms.calc.springs)))
        return atoms

    straight = scene()
    with Maud(straight, logfile=None) as opt:
        opt.run(fmax=1e-300, steps=12)
    restart, trajectory = tmp_path / 'maud.json', tmp_path / 'maud.traj'
    with Maud(scene(), logfile=None, restart=restart, trajectory=trajectory) as opt:
        opt.run(fmax=1e-300, steps=5)
    heavier = scene()
    heavier.calc.set(loads=2 * heavier.calc.parameters['loads'])
    softer = scene()
    softer.calc.set(q=0.5 * softer.calc.parameters['q'])
    for atoms, what in ((heavier, r'loads are other ones \(as many: 16\)'),
                        (softer, r'force densities are other ones \(as many: 60\)')):
        with pytest.raises(ValueError, match=f'of another scene: its {what}'):
            Maud(atoms, logfile=None, restart=restart)
        with pytest.raises(ValueError, match=f'of another scene: its {what}'):
            Maud.resume(atoms, restart=restart, trajectory=trajectory, logfile=None)
    resumed = scene()
    with Maud.resume(resumed, restart=restart, trajectory=trajectory, logfile=None) as opt:
        opt.run(fmax=1e-300, steps=7)
    np.testing.assert_array_equal(resumed.positions, straight.positions)


@pytest.mark.parametrize('seed', [1, 2])
def test_temporary_files_of_killed_writers_are_removed(tmp_path, seed):
    # a kill between writing the restart file's temporary and replacing it
    # leaves the temporary; the next run removes those
    # older than a minute and leaves a live writer's alone
    import time

    from ase_maud.files import atomic_replace as atomic
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 5, seed=seed), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=2)
    old, fresh = tmp_path / '.maud.k1ll3d.tmp.json', tmp_path / '.maud.l1ve.tmp.json'
    for leftover in (old, fresh):
        leftover.write_text('{"format": "half')
    past = time.time() - 2 * atomic.LEFTOVER_SECONDS
    os.utime(old, (past, past))
    with Maud(build('hanging_net', 5, seed=seed), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=2)
    assert not old.exists() and fresh.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        fresh.name, 'maud.json', 'maud.json.arrays']


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


@pytest.mark.parametrize('damage', sorted(DAMAGES))
@pytest.mark.parametrize('seed', [0, 1])
def test_damaged_restart_values_are_named_and_leave_the_atoms(tmp_path, damage, seed):
    edit, match = DAMAGES[damage]
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 8, seed=seed), logfile=None, restart=restart,
              model='springs') as opt:
        opt.run(fmax=1e-9, steps=int(np.random.default_rng(seed).integers(3, 7)))
    document = json.loads(restart.read_text())
    edit(document)
    restart.write_text(json.dumps(document))
    atoms = build('hanging_net', 8, seed=seed)
    start = atoms.positions.copy()
    match = match if match.startswith(':') else ' is damaged: ' + match
    with pytest.raises(ValueError, match=r"restart file '.*maud.json'" + match):
        Maud(atoms, logfile=None, restart=restart)
    np.testing.assert_array_equal(atoms.positions, start)


@pytest.mark.parametrize('seed', [0, 1])
def test_non_finite_restart_rows_are_refused(tmp_path, seed):
    # NaN written into the positions with a matching CRC: refused all the same
    import zlib
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 8, seed=seed), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=3)
    document = json.loads(restart.read_text())
    rows, slot = document['rows'], document['slot']
    arrays = tmp_path / 'maud.json.arrays'
    table = np.fromfile(arrays).reshape(-1, rows)
    table[3 * slot, int(np.random.default_rng(seed).integers(rows))] = np.nan
    table.tofile(arrays)
    document['crc']['state'] = zlib.crc32(table[3 * slot:3 * slot + 3].tobytes())
    restart.write_text(json.dumps(document))
    atoms = build('hanging_net', 8, seed=seed)
    start = atoms.positions.copy()
    with pytest.raises(ValueError, match='hold non-finite numbers'):
        Maud(atoms, logfile=None, restart=restart)
    np.testing.assert_array_equal(atoms.positions, start)
