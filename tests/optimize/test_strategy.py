"""The step strategies alone (Minimise, StepRule, MaudState), their
directions (ase_maud.optimize.directions) and searches (ase_maud.optimize.step_length) on quadratics
with known answers and a matrix model: no calculator, no ASE optimizer (the run
monitor: tests/optimize/test_monitor.py)."""

import io
from dataclasses import replace

import numpy as np
import pytest
from ase.io.jsonio import read_json, write_json

from ase_maud.optimize.directions import (
    MIN_PAIR_COSINE,
    NEWTON_RTOL,
    ModeFollowing,
    lbfgs,
    mode_steps,
    truncated_newton,
)
from ase_maud.optimize.models.base import DampedSolver, StiffnessModel
from ase_maud.optimize.models.registry import MODELS
from ase_maud.optimize.state import MaudState, Point
from ase_maud.optimize.step_length import (
    DAMPING_TOLERANCE,
    bound,
    damping,
    lengths,
    merit_change,
    reach,
    reaches,
    trust_region,
)
from ase_maud.optimize.step_rules import STEP_DEFAULTS, step_rule
from ase_maud.optimize.strategy import compose
from ase_maud.physics.neighbours import NearestDistances


class Quadratic:
    """``E(x) = x.A x / 2 - b.x`` over (n, 3) positions, A random SPD."""

    def __init__(self, seed, n=6, spread=100.0):
        rng = np.random.default_rng(seed)
        q, _ = np.linalg.qr(rng.standard_normal((3 * n, 3 * n)))
        self.A = q @ np.diag(np.geomspace(1.0, spread, 3 * n)) @ q.T
        self.b = rng.standard_normal(3 * n)
        self.n = n
        self.minimum = np.linalg.solve(self.A, self.b).reshape(n, 3)

    def energy(self, x):
        x = x.ravel()
        return 0.5 * x @ self.A @ x - self.b @ x

    def forces(self, x):
        return (self.b - self.A @ x.ravel()).reshape(-1, 3)


class MatrixSolver(DampedSolver):
    """``K^-1 f`` for a dense K over all 3n coordinates, and its damped
    solves (what the exact model's trust region uses)."""

    def __init__(self, K):
        self.K = K
        values = np.linalg.eigvalsh(K)
        self.definite = bool(values.min() > 0)
        self.scale = float(np.abs(values).max())

    def solve(self, forces):
        return np.linalg.solve(self.K, np.ravel(forces)).reshape(-1, 3)

    def dot(self, move):
        return (self.K @ np.ravel(move)).reshape(-1, 3)

    def damped(self, forces):
        def move(mu):
            shifted = self.K + mu * np.eye(len(self.K))
            if np.linalg.eigvalsh(shifted).min() <= 0:
                return None
            return np.linalg.solve(shifted, np.ravel(forces)).reshape(-1, 3)
        return move


class FakeModel(StiffnessModel):
    name = 'fake'

    def at(self, atoms, learnt=None):
        raise AssertionError('the step rule never calls the model itself')


def method(target='minimum', model='exact', maxstep_nn=None, **keywords):
    """The strategy of ``model`` (a name of ``MODELS``, never called: the
    tests hand the local model down); no nearest-distance bound unless
    ``maxstep_nn`` is given."""
    stiffness = MODELS[model](target=target)
    rule = replace(step_rule(stiffness, **keywords), maxstep_nn=maxstep_nn)
    return compose(stiffness, rule, NearestDistances())


def raised(last_merit, last_noise, last_forces, move, merit, forces, noise, energy):
    """Whether the step raised the merit: its change beyond the slack."""
    change, slack = merit_change(last_merit, last_noise, last_forces, move, merit, forces,
                                 noise, energy)
    return change > slack


def uphill(rule, state, x, merit, forces, noise):
    """Whether the step from ``state.last`` to ``x`` raised the merit."""
    last = state.last
    return raised(last.merit, last.noise, last.forces, x - last.x, merit, forces, noise,
                  energy=rule.model.target == 'minimum')


def start(seed, quadratic):
    return np.random.default_rng(seed + 100).standard_normal((quadratic.n, 3)) * 10


def relax(rule, quadratic, x, K, steps=500, fmax=1e-9):
    """Drive ``rule`` with exact energies and forces; return the positions,
    the number of evaluations and the energies of the accepted points."""
    state = rule.start()
    accepted = []
    for evaluation in range(1, steps + 1):
        forces = quadratic.forces(x)
        if np.linalg.norm(forces, axis=1).max() < fmax:
            return x, evaluation, accepted
        move = rule.step(state, x, quadratic.energy(x), forces, 0.0,
                         lambda at: MatrixSolver(K))
        accepted.append(state.last.merit)
        x = state.last.x + move
        rule.moved(state, x)
    raise AssertionError(f'not converged in {steps} evaluations')


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_exact_model_is_one_newton_step(seed):
    quadratic = Quadratic(seed)
    x, evaluations, _ = relax(method(), quadratic, start(seed, quadratic), quadratic.A)
    assert evaluations == 2   # the start, then the minimum
    np.testing.assert_allclose(x, quadratic.minimum, atol=1e-9)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_lbfgs_memory_over_a_poor_model_converges_downhill(seed):
    quadratic = Quadratic(seed, spread=30.0)
    K = np.eye(3 * quadratic.n) * 30.0   # the stiffest curvature: no overshoot
    memoryless, plain, _ = relax(method(model='global', memory=0), quadratic,
                                 start(seed, quadratic), K, steps=5000)
    x, with_memory, energies = relax(method(model='global', memory=30), quadratic,
                                     start(seed, quadratic), K)
    np.testing.assert_allclose(x, quadratic.minimum, atol=1e-8)
    assert with_memory < plain / 3
    assert np.all(np.diff(energies) <= 1e-12 * np.abs(energies[1:]))


@pytest.mark.parametrize('seed', range(4))
def test_lbfgs_is_the_bfgs_inverse_update_of_its_initial_model(seed):
    """The two-loop recursion over m pairs applies the matrix the BFGS
    inverse update builds from ``K^-1``, pair by pair, oldest first:
    ``H <- (I - rho s y^T) H (I - rho y s^T) + rho s s^T``."""
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(3, 12)), int(rng.integers(1, 30))
    root = rng.normal(size=(3 * n, 3 * n))
    K = root @ root.T + 3 * n * np.eye(3 * n)
    pairs = []
    for _ in range(m):
        s = rng.normal(size=(n, 3))
        y = (K @ s.ravel() + 0.3 * rng.normal(size=3 * n)).reshape(n, 3)   # s.y > 0
        pairs.append((s, y))
    H = np.linalg.inv(K)
    for s, y in pairs:
        rho = 1.0 / np.vdot(s, y)
        left = np.eye(3 * n) - rho * np.outer(s.ravel(), y.ravel())
        H = left @ H @ left.T + rho * np.outer(s.ravel(), s.ravel())
    forces = rng.normal(size=(n, 3))
    direction = lbfgs(lambda f: np.linalg.solve(K, f.ravel()).reshape(f.shape), forces, pairs)
    np.testing.assert_allclose(direction.ravel(), H @ forces.ravel(), rtol=1e-9,
                               atol=1e-12 * np.abs(H @ forces.ravel()).max())


def test_an_uphill_step_is_taken_back_with_half_the_gamma():
    quadratic = Quadratic(3)
    rule = method()
    state = rule.start()
    x0 = start(3, quadratic)
    too_soft = MatrixSolver(quadratic.A / 3)   # overshoots by 3
    move = rule.step(state, x0, quadratic.energy(x0), quadratic.forces(x0), 0.0,
                     lambda at: too_soft)
    x1 = x0 + move
    rule.moved(state, x1)
    assert uphill(rule, state, x1, quadratic.energy(x1), quadratic.forces(x1), 0.0)
    again = rule.step(state, x1, quadratic.energy(x1), quadratic.forces(x1), 0.0,
                      lambda at: pytest.fail('the solver of the start is kept'))
    assert state.last.x is not x1 and np.array_equal(state.last.x, x0)
    assert state.gamma == 0.5
    np.testing.assert_allclose(again, 0.5 * move)


def bfgs_rule(learn_rises=True):
    """The bfgs model's strategy with no length bound (the tests hand the
    local model down)."""
    stiffness = MODELS['bfgs']()
    rule = replace(step_rule(stiffness), maxstep_nn=None, maxstep=None,
                   learn_rises=learn_rises)
    return compose(stiffness, rule, NearestDistances())


@pytest.mark.parametrize('seed', range(3))
def test_a_rise_is_learnt_from_and_retaken_within_the_cut(seed):
    """The bfgs model's rule takes a step that raised the energy back to
    where it began and learns from it: its secant pair joins the memory,
    the model's kappa and gamma are unchanged, and the next move, the
    L-BFGS move with that pair, is no longer than the cubic cut (1/3 for a
    threefold overshoot along the step on a quadratic) of the step."""
    quadratic = Quadratic(seed)
    rule = bfgs_rule()
    state = rule.start()
    x0 = start(seed, quadratic)
    too_soft = MatrixSolver(quadratic.A / 3)   # three times the Newton move
    move = rule.step(state, x0, quadratic.energy(x0), quadratic.forces(x0), 0.0,
                     lambda at: too_soft)
    x1 = x0 + move
    rule.moved(state, x1)
    assert uphill(rule, state, x1, quadratic.energy(x1), quadratic.forces(x1), 0.0)
    model, gamma = dict(state.model), state.gamma
    again = rule.step(state, x1, quadratic.energy(x1), quadratic.forces(x1), 0.0,
                      lambda at: pytest.fail('the solver of the start is kept'))
    assert np.array_equal(state.last.x, x0)                # taken back
    assert state.model == model and state.gamma == gamma
    (s, y), = state.pairs
    np.testing.assert_allclose(s, x1 - x0)
    np.testing.assert_allclose(y, quadratic.forces(x0) - quadratic.forces(x1))
    longest = np.linalg.norm(again, axis=1).max()
    assert longest <= np.linalg.norm(move, axis=1).max() / 3 * (1 + 1e-9)
    assert quadratic.energy(x0 + again) < quadratic.energy(x0)


@pytest.mark.parametrize('seed', range(3))
def test_reaches_each_point_and_never_below_zero(seed):
    """Each point's reach puts it on its limit (its smallest is ``reach``);
    a point that does not move reaches without end, and one on its limit
    (by rounding just beyond it) moving outward reaches 0, not a negative
    root that would turn a move around."""
    rng = np.random.default_rng(seed)
    start, step = 0.1 * rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    limit = np.full(5, 0.5)
    start[3] = [0.5 * (1 + 1e-15), 0.0, 0.0]
    step[3] = [1.0, 0.0, 0.0]                      # on its limit, outward
    step[4] = 0.0                                  # not moving
    t = reaches(start, step, limit)
    moving = [0, 1, 2]
    np.testing.assert_allclose(np.linalg.norm(start[moving] + t[moving, None] * step[moving],
                                              axis=1), 0.5)
    assert t[3] == 0.0 and t[4] == np.inf
    assert reach(start, step, limit) == 0.0


@pytest.mark.parametrize('seed', range(3))
def test_a_retake_past_where_the_step_began_keeps_each_jump_within_its_limit(seed):
    """A point whose rejected move reached its 0.2 limit and that the
    retake sends back past where the step began jumps at most its limit
    from where it is (so it lands where the step began), while the other
    points take the model's retake: the move is not scaled to nothing for
    that one point (which had spent a call on the point already known)."""
    rng = np.random.default_rng(seed)
    stiffness = MODELS['bfgs']()
    rule = compose(stiffness, replace(step_rule(stiffness), maxstep_nn=None),
                   NearestDistances())
    x0 = rng.normal(size=(3, 3))
    f0 = rng.normal(size=(3, 3))
    f0[0] = [-1.0, 0.0, 0.0]                       # point 0 pulled along -x
    rejected = 0.05 * rng.normal(size=(3, 3))
    rejected[0] = [0.2, 0.0, 0.0]                  # ... it went +x, to its limit
    f1 = f0 - 10.0 * rejected                      # a stiff wall along the step
    state = MaudState(gamma=1.0, last=Point(x0, 0.0, f0), v=rejected,
                      solver=stiffness.at(None))
    again = rule.step(state, x0 + rejected, 1.0, f1, 0.0,
                      lambda at: pytest.fail('the solver of the start is kept'))
    assert np.array_equal(state.last.x, x0)        # taken back
    jump = np.linalg.norm(again - rejected, axis=1)
    assert np.all(jump <= 0.2 * (1 + 1e-12))
    np.testing.assert_allclose(again[0], 0.0, atol=1e-12)   # back where it began
    assert np.linalg.norm(again[1:], axis=1).min() > 1e-3   # the others move on
    assert np.vdot(f0, again) > 0                            # downhill


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('kappa', [0.3, 3.0])
def test_learning_from_rises_saves_evaluations_of_a_poor_model(seed, kappa):
    """On a quadratic (curvatures 1 to 100) from the model ``kappa I``
    (soft: its moves overshoot), learning the pairs of the steps taken back
    reaches the minimum in at most 0.85 of the evaluations of the plain
    cut (measured: 28-31 against 36-57)."""
    quadratic = Quadratic(seed)
    K = np.eye(3 * quadratic.n) * kappa
    runs = [relax(bfgs_rule(learn), quadratic, start(seed, quadratic), K, fmax=1e-6)
            for learn in (False, True)]
    (_, plain, _), (x, learnt, energies) = runs
    np.testing.assert_allclose(x, quadratic.minimum, atol=1e-5)
    assert learnt <= 0.85 * plain
    assert np.all(np.diff(energies) <= 1e-12 * np.abs(energies[1:]))   # downhill only


@pytest.mark.parametrize('seed', range(3))
def test_a_line_search_cut_shortens_a_move_the_bound_clipped(seed):
    """The springs rule (a line search over a bounded move): a move the
    scene-size bound clipped that raised the energy is followed by the same
    move cut by the line search's factor, not by the same clipped move
    again (which had left gamma halving to nothing: a collapsing ring with
    chords stagnated at its second step)."""
    quadratic = Quadratic(seed)
    rule = method(model='springs')
    state = rule.start()
    x0 = quadratic.minimum + 1e-3 * start(seed, quadratic)   # near it, a wide scene
    far_too_soft = MatrixSolver(quadratic.A / 1e6)   # overshoots a millionfold
    move = rule.step(state, x0, quadratic.energy(x0), quadratic.forces(x0), 0.0,
                     lambda at: far_too_soft)
    size = np.linalg.norm(x0 - x0.mean(axis=0), axis=1).max()
    assert np.linalg.norm(move, axis=1).max() == pytest.approx(size)   # clipped
    x1 = x0 + move
    rule.moved(state, x1)
    assert uphill(rule, state, x1, quadratic.energy(x1), quadratic.forces(x1), 0.0)
    again = rule.step(state, x1, quadratic.energy(x1), quadratic.forces(x1), 0.0,
                      lambda at: pytest.fail('the solver of the start is kept'))
    assert 0.1 <= state.gamma <= 0.5
    np.testing.assert_allclose(again, state.gamma * move, rtol=1e-12)


def test_energies_within_their_noise_are_decided_by_the_forces():
    quadratic = Quadratic(4)
    rule = method()
    x0 = quadratic.minimum + 1e-4
    x1 = quadratic.minimum + 0.5e-4
    state = rule.start()
    state.last = Point(x0, quadratic.energy(x0), quadratic.forces(x0), 0.0)
    # a merit that looks higher, within a noise of 1e-3, but downhill by the
    # trapezoid rule of the forces: accepted
    looks_higher = quadratic.energy(x1) + 1e-6 * abs(quadratic.energy(x1))
    assert not uphill(rule, state, x1, looks_higher, quadratic.forces(x1), 1e-3)
    assert uphill(rule, state, x1, looks_higher, quadratic.forces(x1), 1e-9)


def test_two_energies_are_compared_within_their_errors_summed():
    """Each energy may be off by its own error, so their difference by the
    sum: a merit that looks higher by 1.5 times either error, downhill by
    the forces, is no rise when both carry that error; it is one when only
    one does."""
    quadratic = Quadratic(5)
    x0 = quadratic.minimum + 1e-4
    x1 = quadratic.minimum + 0.5e-4
    last, forces0, forces1 = 1e6, quadratic.forces(x0), quadratic.forces(x1)
    assert np.vdot(forces0 + forces1, x1 - x0) > 0          # downhill by the forces
    looks_higher = last * (1 + 1.5e-3)
    assert not raised(last, 1e-3, forces0, x1 - x0, looks_higher, forces1, 1e-3,
                      energy=True)
    assert raised(last, 0.0, forces0, x1 - x0, looks_higher, forces1, 1e-3, energy=True)
    # judged by the forces, the change is the trapezoid estimate, no slack
    change, slack = merit_change(last, 1e-3, forces0, x1 - x0, looks_higher, forces1,
                                 1e-3, energy=True)
    assert slack == 0.0
    assert change == pytest.approx(quadratic.energy(x1) - quadratic.energy(x0), rel=1e-9)


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('error', [-0.9, 0.0, 0.9])
def test_a_cut_within_the_noise_is_judged_by_the_forces(seed, error):
    """A step that overshot the minimum along it threefold, whose energies
    are within their noise (a large energy, 1e9 above the quadratic's, off
    by ``error`` times the noise), is cut to the minimum along the move,
    1/3, from the forces alone (the trapezoid estimate is exact for a
    quadratic), whatever the energies' error."""
    quadratic = Quadratic(seed)
    rule = method(interpolate=True)
    state = rule.start()
    x0 = start(seed, quadratic)
    noise, offset = 1e-3, 1e9
    too_soft = MatrixSolver(quadratic.A / 3)   # three times the Newton move
    move = rule.step(state, x0, offset + quadratic.energy(x0), quadratic.forces(x0),
                     noise, lambda at: too_soft)
    newton = np.linalg.solve(quadratic.A, quadratic.forces(x0).ravel()).reshape(-1, 3)
    np.testing.assert_allclose(move, 3 * newton, rtol=1e-9)
    x1 = x0 + move
    rule.moved(state, x1)
    reported = offset + quadratic.energy(x1) + error * noise * offset
    assert abs(reported - state.last.merit) < 2 * noise * offset   # within the noise
    again = rule.step(state, x1, reported, quadratic.forces(x1), noise,
                      lambda at: pytest.fail('the solver of the start is kept'))
    assert np.array_equal(state.last.x, x0)                # taken back
    assert state.gamma == pytest.approx(1 / 3, rel=1e-9)
    np.testing.assert_allclose(again, newton, rtol=1e-8)


def test_nearly_degenerate_secant_pairs_are_not_kept():
    rule = method(model='global', memory=10)
    state = rule.start()
    x0 = np.zeros((2, 3))
    state.last = Point(x0, 0.0, np.ones((2, 3)), 0.0)
    s = np.ones((2, 3))
    y = np.zeros((2, 3))
    y[0, 0], y[0, 1] = 1.0, -1.0
    y[0, 1] += 1e-3 * MIN_PAIR_COSINE * np.sqrt(12)  # s.y / (|s| |y|) below the bound
    rule._accept(state, x0 + s, state.last.forces - y)
    assert state.pairs == []
    y[0, 1] = 1.0
    rule._accept(state, x0 + s, state.last.forces - y)
    assert len(state.pairs) == 1


def test_a_direction_that_is_not_downhill_clears_the_memory():
    rule = method(model='global', memory=10)
    forces = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    state = rule.start()
    state.last = Point(np.zeros((2, 3)), 0.0, forces, 0.0)
    state.solver = MatrixSolver(np.eye(6))
    # a pair of negative curvature, as rounding could leave: the two-loop
    # recursion then points uphill
    state.pairs = [(forces.copy(), -4.0 * forces)]
    assert not np.vdot(lbfgs(state.solver.solve, forces, state.pairs), forces) > 0
    move = rule._move(state)
    assert state.pairs == []
    np.testing.assert_array_equal(move, state.gamma * forces)


@pytest.mark.parametrize('seed', [0, 1])
def test_each_point_moves_at_most_maxstep_nn_of_its_nearest_distance(seed):
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 5, (12, 3))
    rule = method(maxstep_nn=0.3)
    state = rule.start()
    big = rng.standard_normal((12, 3)) * 100
    move = rule.step(state, x, 0.0, big, 0.0, lambda at: MatrixSolver(np.eye(36)))
    limit = 0.3 * NearestDistances()(x)
    assert np.all(np.linalg.norm(move, axis=1) <= limit * (1 + 1e-12))
    unit = big / np.linalg.norm(big, axis=1)[:, None]
    np.testing.assert_allclose(move / np.linalg.norm(move, axis=1)[:, None], unit)


def test_momentum_restarts_on_an_overshoot():
    rule = method(model='nodal')
    state = rule.start()
    x = np.zeros((1, 3))
    solver = MatrixSolver(np.eye(3))
    rule.step(state, x, 0.0, np.array([[1.0, 0, 0]]), 0.0, lambda at: solver)
    rule.moved(state, x + [[1.0, 0, 0]])
    gamma = state.gamma * rule.rule.gamma_growth
    # the next force points back: the move is dropped, gamma shrinks
    move = rule.step(state, x + [[1.0, 0, 0]], -1.0, np.array([[-1.0, 0, 0]]), 0.0,
                     lambda at: solver)
    assert state.gamma == pytest.approx(gamma * rule.rule.overshoot_shrink)
    np.testing.assert_allclose(move, [[-state.gamma, 0, 0]])


def test_step_rule_merges_defaults_model_and_keywords():
    rule = step_rule(MODELS['global'](), gamma_max=0.8, memory=None)
    assert rule.gamma_max == 0.8
    assert rule.memory == STEP_DEFAULTS[MODELS['global']]['memory']
    assert rule.gamma_growth == STEP_DEFAULTS['common']['gamma_growth']
    assert step_rule(MODELS['global'](target='stationary')).memory == 0
    assert step_rule(FakeModel()).beta_max == STEP_DEFAULTS[MODELS['nodal']]['beta_max']


def test_state_survives_json():
    rng = np.random.default_rng(5)
    state = MaudState(gamma=0.3, k=4, v=rng.standard_normal((3, 3)),
                      last=Point(rng.standard_normal((3, 3)), 1.5,
                                 rng.standard_normal((3, 3)), 1e-7),
                      pairs=[(rng.standard_normal((3, 3)), rng.standard_normal((3, 3)))],
                      model={'kappa': 2.5})
    buffer = io.StringIO()
    write_json(buffer, state.todict())
    buffer.seek(0)
    again = MaudState.fromdict(read_json(buffer))
    assert again.todict().keys() == state.todict().keys()
    for name in ('gamma', 'k', 'model'):
        assert getattr(again, name) == getattr(state, name)
    np.testing.assert_array_equal(again.v, state.v)
    np.testing.assert_array_equal(again.last.x, state.last.x)
    np.testing.assert_array_equal(again.pairs[0][1], state.pairs[0][1])


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('uphill', [True, False])
def test_mode_steps_are_newton_where_the_curvature_serves_else_the_whole_reach(seed, uphill):
    """Along each mode: the Newton step ``-g/b`` (the stationary point of the
    quadratic) where the curvature has the sign sought and that step is
    within reach, else a step of the whole reach; every step climbs
    (``uphill``) or falls, and none is longer than its reach."""
    rng = np.random.default_rng(seed)
    b, g = rng.normal(size=40), rng.normal(size=40)
    reach = rng.uniform(0.1, 3.0, size=40)
    s = mode_steps(b, g, reach, uphill)
    right = b < 0 if uphill else b > 0
    newton = right & (np.abs(g / b) <= reach)
    assert newton.any() and (~newton).any()
    np.testing.assert_allclose(s[newton], -g[newton] / b[newton], rtol=1e-14)
    np.testing.assert_allclose(np.abs(s[~newton]), reach[~newton], rtol=1e-14)
    assert np.all(np.sign(g * s) == (1 if uphill else -1))
    assert np.all(np.abs(s) <= reach * (1 + 1e-14))


def test_mode_steps_at_zero_curvature_or_gradient_are_finite():
    """A flat mode, or a symmetric point with no gradient, gives a finite step."""
    b, reach = np.array([0.0, -2.0, 1.0, 0.0]), np.ones(4)
    for g in (np.zeros(4), np.array([1.0, 0.0, 1e-300, -1e-14])):
        for uphill in (True, False):
            assert np.isfinite(mode_steps(b, g, reach, uphill)).all()


def _newton_problem(seed, n=12, negative=0):
    """A random symmetric H on (n, 3) moves (``negative`` of its eigenvalues
    below 0), its forces, and a diagonal preconditioner."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((3 * n, 3 * n)))
    values = np.geomspace(0.01, 10.0, 3 * n)
    values[:negative] *= -1
    hessian = q @ np.diag(values) @ q.T
    diagonal = np.abs(np.diag(hessian)) + 0.1
    forces = rng.standard_normal((n, 3))
    return (hessian, lambda d: (hessian @ d.ravel()).reshape(-1, 3),
            lambda r: r / diagonal.reshape(-1, 3), forces)


@pytest.mark.parametrize('seed', range(4))
def test_truncated_newton_solves_within_a_wide_region(seed):
    """With room enough, the move solves ``H d = f`` to ``NEWTON_RTOL``, and
    the ``H d`` returned is ``H`` times the move."""
    hessian, dot, precondition, forces = _newton_problem(seed)
    move, curved = truncated_newton(dot, precondition, forces, np.full(len(forces), 1e9))
    np.testing.assert_allclose(curved.ravel(), hessian @ move.ravel(), atol=1e-10)
    residual = np.linalg.norm(forces - curved) / np.linalg.norm(forces)
    assert residual <= NEWTON_RTOL


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('negative', [0, 3])
def test_truncated_newton_stays_within_each_bound_and_descends(seed, negative):
    """With tight bounds, or negative curvature, the move keeps every point
    within its bound, touches one of them, and lowers the quadratic model
    ``-f.d + d.H d / 2``; ``H d`` is still ``H`` times the move."""
    hessian, dot, precondition, forces = _newton_problem(seed, negative=negative)
    limit = np.random.default_rng(seed).uniform(0.01, 0.05, len(forces))
    move, curved = truncated_newton(dot, precondition, forces, limit)
    lengths = np.linalg.norm(move, axis=1)
    assert np.all(lengths <= limit * (1 + 1e-12))
    assert np.isclose(lengths / limit, 1.0, rtol=1e-9).any()
    np.testing.assert_allclose(curved.ravel(), hessian @ move.ravel(), atol=1e-10)
    assert -np.vdot(forces, move) + 0.5 * np.vdot(move, curved) < 0


# -- the trust region (search.trust_region) ---------------------------------------

def _quadratic_model(seed, n=8, negative=0):
    """A random symmetric K on (n, 3) moves (``negative`` eigenvalues below
    0) as a MatrixSolver, and forces."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((3 * n, 3 * n)))
    values = np.geomspace(0.05, 20.0, 3 * n)
    values[:negative] *= -1
    return MatrixSolver(q @ np.diag(values) @ q.T), rng.standard_normal((n, 3)), values


@pytest.mark.parametrize('seed', range(4))
def test_trust_region_keeps_a_newton_move_that_fits(seed):
    model, forces, _ = _quadratic_model(seed)
    newton = model.solve(forces)
    limit = np.full(len(forces), 2.0 * np.linalg.norm(newton, axis=1).max())
    assert trust_region(model, forces, newton, 1.0, limit) is newton


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('gamma', [1.0, 0.5])
def test_dogleg_of_a_definite_model_reaches_the_limit_downhill(seed, gamma):
    """A Newton move too long for the limits is cut on the dogleg path: its
    ``gamma`` times touches a limit and stays within every one, and the
    quadratic model ``-f.d + d.K d / 2`` falls."""
    model, forces, _ = _quadratic_model(seed)
    newton = model.solve(forces)
    limit = np.random.default_rng(seed).uniform(0.05, 0.2, len(forces)) * np.linalg.norm(
        newton, axis=1).max()
    move = trust_region(model, forces, newton, gamma, limit)
    ratio = gamma * np.linalg.norm(move, axis=1) / limit
    assert ratio.max() == pytest.approx(1.0, rel=1e-9)
    assert -np.vdot(forces, move) + 0.5 * np.vdot(move, model.dot(move)) < 0


@pytest.mark.parametrize('seed', range(4))
def test_damping_of_an_indefinite_model_is_the_smallest_that_fits(seed):
    """An indefinite model is damped to ``(K + mu I)^-1 f`` with ``K + mu I``
    definite, the move within the limits, and no ``mu`` 1 % smaller that
    fits unless the move is already within ``DAMPING_TOLERANCE`` of its
    limit (the search stops there)."""
    model, forces, values = _quadratic_model(seed, negative=3)
    model.definite = False
    newton = model.solve(forces)
    limit = np.full(len(forces), 0.3)
    move = trust_region(model, forces, newton, 1.0, limit)
    assert np.linalg.norm(move, axis=1).max() <= 0.3 * (1 + 1e-12)
    flat = move.ravel()
    mu = np.vdot(forces.ravel() - model.K @ flat, flat) / np.vdot(flat, flat)
    assert mu > -values.min()
    np.testing.assert_allclose((model.K + mu * np.eye(len(flat))) @ flat, forces.ravel(),
                               rtol=1e-8, atol=1e-10)
    smaller = model.damped(forces)(0.99 * mu)
    longest = np.linalg.norm(move, axis=1).max()
    assert (smaller is None or np.linalg.norm(smaller, axis=1).max() > 0.3
            or longest >= 0.3 * (1 - DAMPING_TOLERANCE))


@pytest.mark.parametrize('seed', range(16))
def test_damping_finds_its_move_in_a_few_solves(seed):
    """The secant from above, then false position, in log mu: a move within
    1 % of the longest that fits the limits, in at most 7 damped solves with
    the bracket's growth (3-6 on these seeds; false position from the
    bracket's geometric middle took 7-11, 14 bisections 15 or more), on
    indefinite quadratics whose limits are a tenth to half of Newton's
    move."""
    model, forces, _ = _quadratic_model(seed, negative=2)
    rng = np.random.default_rng(seed)
    limit = rng.uniform(0.1, 0.5, len(forces)) * np.linalg.norm(model.solve(forces), axis=1)
    solve, mus = model.damped(forces), []

    def counted(mu):
        mus.append(mu)
        return solve(mu)

    move = damping(counted, 1.0, limit, model.scale)
    ratio = np.linalg.norm(move, axis=1) / limit
    assert ratio.max() <= 1 + 1e-12
    assert ratio.max() >= 0.99
    assert len(mus) <= 7


@pytest.mark.parametrize('seed', range(3))
def test_lengths_are_numpys_norm_to_the_last_bit(seed):
    """The step layer's row lengths are ``np.linalg.norm(x, axis=1)``'s
    digits exactly, over scales from 1e-150 to 1e150, with zero and signed
    zero rows."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((40, 3)) * 10.0 ** rng.integers(-150, 150, size=(40, 1))
    x[:3] = [[0.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [-0.0, 2.0, 0.0]]
    assert lengths(x).tobytes() == np.linalg.norm(x, axis=1).tobytes()


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('whole', [False, True])
def test_bound_is_numpys_formula_to_the_last_bit(seed, whole):
    """The compiled per-point scales of :func:`bound` give the moves of its
    numpy formula exactly (limits above, below and at a move's length)."""
    rng = np.random.default_rng(seed)
    step = rng.standard_normal((30, 3)) * 10.0 ** rng.uniform(-3, 3)
    length = np.linalg.norm(step, axis=1)
    limit = length * rng.choice([0.5, 1.0, 2.0], size=30)
    limit[:2] = [np.inf, 0.0]
    step[2] = 0.0
    scale = np.divide(limit, length, out=np.ones_like(length), where=length > limit)
    expected = step * (scale.min(initial=1.0) if whole else scale[:, None])
    assert bound(step, limit, whole).tobytes() == expected.tobytes()


def test_exact_models_solver_is_cholesky_where_definite_and_eigen_where_not():
    """The exact model's local model declares which: a definite Hessian gets
    the Cholesky solver (dogleg), an indefinite one the saddle-free eigen
    solver (damped), and both solve ``|K| d = f``."""
    from ase_maud.optimize.models.exact import ExactModel
    from ase_maud.scenes.catalogue import build
    model = ExactModel()
    minimum = build('dimer')
    minimum.set_distance(0, 1, 1.0)   # the dimer's minimum, L = a
    definite = model.at(minimum)
    assert isinstance(definite, DampedSolver) and definite.definite
    squeezed = build('all_pairs', 6, seed=1)
    indefinite = model.at(squeezed)
    assert not indefinite.definite
    hessian = squeezed.calc.get_hessian(squeezed)
    values, vectors = np.linalg.eigh(hessian)
    forces = np.random.default_rng(0).standard_normal((len(squeezed), 3))
    move = indefinite.solve(forces).ravel()
    safe = np.maximum(np.abs(values), model.floor * np.abs(values).max())
    np.testing.assert_allclose(move, vectors @ ((vectors.T @ forces.ravel()) / safe),
                               rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize('seed', [0, 1])
def test_a_move_given_as_mode_starts_the_first_lowest_modes(seed):
    """``ModeFollowing.guess``: the move given as ``mode``, of unit length, in a
    block of one (the first LOBPCG's start); nothing for an index or no mode."""
    move = np.random.default_rng(seed).normal(size=(7, 3))
    guess = ModeFollowing(1, move).guess()
    assert guess.shape == (1, 7, 3)
    assert np.linalg.norm(guess) == pytest.approx(1.0)
    assert np.allclose(guess[0] * np.linalg.norm(move), move)
    assert ModeFollowing(1, 2).guess() is None and ModeFollowing(1).guess() is None
