"""Hostile inputs, class by class: what each gets now.

Prints a markdown table (docs/hard_cases.md): per class, the inputs tried
and how many got a correct answer, a ValueError, a MaudError, or anything
else (a defect: a raw TypeError, a non-finite position, a stale or wrong
result). Run with the threads pinned::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python tools/hostile_sweep.py

The SIGKILL class is tests/test_restart_kill.py (5 kills at seeded moments).
"""

from __future__ import annotations

import inspect
import sys
import tempfile
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron
from ase.io import read
from ase.md.verlet import VelocityVerlet
from ase.optimize import BFGS
from ase.optimize.basin import BasinHopping

from ase_maud import Maud, MaudCalculator, MaudError
from ase_maud.checks import RULES
from ase_maud.scenes import build

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'tests'))
from doubles import PoisonedCalculator  # noqa: E402  (the tests' own double)

#: Maud's numeric keywords (RULES holds the rule of each).
KEYWORDS = [name for name in inspect.signature(Maud).parameters
            if name in RULES and not RULES[name].choices]

HOSTILE = [0, 0.0, -1, -1.0, np.nan, np.inf, -np.inf, None, 'x', '1', True, False,
           [1.0], 1e-300, 1e300, 10**400, 0.5, 2]
FMAX = [0, -1, np.nan, np.inf, -np.inf, None, 'x', True, [0.1], 1e-300, 1e300, 1e-6]
STEPS = [-1, np.nan, 1.5, 'x', None, True, np.inf, 10**400, 0, 5, 1e3, 2000]


def outcome(run) -> str:
    """'correct', 'ValueError', 'MaudError' or 'other: ...' for ``run()``,
    which returns True for a correct answer."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            return 'correct' if run() else 'other: wrong answer'
    except (ValueError, MaudError) as error:
        kind = 'MaudError' if isinstance(error, MaudError) else 'ValueError'
        return f'{kind}: {error}' if str(error) else f'other: {kind} without a message'
    except Exception as error:   # noqa: BLE001 (counted as a defect)
        return f'other: {type(error).__name__}: {error}'


def minimum():
    atoms = build('ring', 8, seed=1)
    with BFGS(atoms, logfile=None) as opt:
        opt.run(fmax=1e-9, steps=5000)
    return atoms.get_potential_energy()


E_RING = minimum()


def relax_ring(fmax=1e-6, steps=2000, **keywords):
    """A correct answer: finite positions, and converged to the ring's
    minimum, or honestly not converged (fmax above the request)."""
    atoms = build('ring', 8, seed=1)
    try:
        with Maud(atoms, **{'logfile': None, **keywords}) as opt:
            converged = opt.run(fmax=fmax, steps=steps)
    finally:
        assert np.isfinite(atoms.positions).all()
    largest = np.linalg.norm(atoms.get_forces(), axis=1).max()
    if converged != (largest < fmax):
        return False
    energy = atoms.get_potential_energy()
    return not converged or fmax > 1e-3 or abs(energy - E_RING) < 1e-8 * E_RING


def run_arguments():
    return [(lambda f=f, s=s: relax_ring(f, s)) for f in FMAX for s in STEPS]


def keywords():
    names = [n for n in KEYWORDS if n not in ('fmax', 'steps')] + ['model', 'method', 'target']
    return [(lambda n=n, v=v: relax_ring(**{n: v})) for n in names for v in HOSTILE]


def files(directory: Path):
    cases = [('logfile', 1), ('logfile', True), ('logfile', 3.5), ('trajectory', 2),
             ('restart', object()), ('trajectory', directory / 'missing' / 'x.traj'),
             ('logfile', directory / 'missing' / 'x.log'),
             ('restart', directory / 'missing' / 'x.json'), ('restart', directory),
             ('trajectory', ''), ('append_trajectory', 'yes'), ('append_trajectory', None),
             ('trajectory', directory / 'ok.traj'), ('restart', directory / 'ok.json'),
             ('logfile', directory / 'ok.log')]
    return [(lambda n=n, v=v: relax_ring(**{n: v})) for n, v in cases]


def small_scales():
    """A move of a thousandth of ``a`` changes the energy at every scale."""
    def moved(a):
        atoms = build('ring', 8, seed=1, a=a, Q=1.0)
        before = atoms.get_potential_energy()
        atoms.positions[3, 0] += 1e-3 * a
        return atoms.get_potential_energy() != before
    return [(lambda a=a: moved(a)) for a in (1e-12, 1e-10, 1e-6, 1.0, 1e6, 1e12)]


def non_finite(directory: Path):
    def case(scene, what, value, call):
        if scene == 'emt':
            atoms = Icosahedron('Cu', 2)
            atoms.rattle(0.05, seed=1)
            inner = EMT()
        else:
            atoms = build('hanging_net', 5, seed=1)
            inner = MaudCalculator(**atoms.calc.parameters)
        atoms.calc = PoisonedCalculator(inner, call, what, value)
        traj = directory / f'{scene}{what}{value}{call}.traj'
        try:
            with Maud(atoms, logfile=None, trajectory=traj) as opt:
                opt.run(fmax=1e-6)
        finally:
            assert np.isfinite(atoms.positions).all()
            if traj.exists() and traj.stat().st_size:
                assert all(np.isfinite(f.get_forces()).all() for f in read(traj, ':'))
        return False   # a run that ends without an error missed the value
    return [(lambda c=c: case(*c)) for c in
            [(s, w, v, k) for s in ('emt', 'maud') for w in ('energy', 'forces')
             for v in (np.nan, np.inf, -np.inf) for k in (1, 2, 4, 8)]]


def extreme_scales():
    """H2's class: a Maud relaxation at extreme ``a`` and a pair 1e-110 apart."""
    def relax(a):
        atoms = build('ring', 8, seed=1, a=a)
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-6 * a, steps=500)
        return (np.isfinite(atoms.positions).all()
                and abs(atoms.get_potential_energy() / a**2 - E_RING) < 1e-7 * E_RING)

    def close(d):
        atoms = build('all_pairs', 6, seed=1)
        atoms.positions[0] = 0.0
        atoms.positions[1] = [d, 0, 0]
        energy, forces = atoms.get_potential_energy(), atoms.get_forces()
        return np.isfinite(energy) and np.isfinite(forces).all()
    return ([(lambda a=a: relax(a)) for a in (1e-105, 1e-60, 1e60, 1e100)]
            + [(lambda d=d: close(d)) for d in (1e-110, 1e-200, 1e-300)])


def fmm_near_pairs():
    """H2's class: the fmm backend with a pair closer than 1e-12 of the box."""
    def case(d):
        atoms = build('all_pairs', 40, seed=1)
        atoms.positions[0] = 0.0
        atoms.positions[1] = [d, 0, 0]
        reference = atoms.copy()
        reference.calc = MaudCalculator(**{**atoms.calc.parameters, 'backend': 'numpy'})
        atoms.calc = MaudCalculator(**{**atoms.calc.parameters, 'backend': 'fmm'})
        return np.allclose(atoms.get_forces(), reference.get_forces(), rtol=1e-6,
                           atol=1e-6 * np.abs(reference.get_forces()).max())
    return [(lambda d=d: case(d)) for d in (1e-6, 1e-10, 1e-13, 1e-15)]


def planar_drivers():
    def hop(name):
        atoms = build(name, seed=2)
        np.random.seed(3)
        with BasinHopping(atoms, temperature=1.0, dr=0.5, optimizer=Maud, fmax=1e-4,
                          logfile=None, optimizer_logfile=None, trajectory=None,
                          local_minima_trajectory=None) as hopping:
            hopping.run(3)
        return np.ptp(atoms.positions[:, 2]) == 0

    def md(name):
        atoms = build(name, seed=2)
        atoms.set_momenta(np.random.default_rng(1).normal(size=(len(atoms), 3)))
        with VelocityVerlet(atoms, timestep=0.01) as dyn:
            dyn.run(20)
        return np.ptp(atoms.positions[:, 2]) == 0
    names = ('ring', 'net2d', 'all_pairs2d')
    return [(lambda n=n: hop(n)) for n in names] + [(lambda n=n: md(n)) for n in names]


def unclear_errors():
    """Bad inputs of the scene builders and the calculator: a ValueError
    whose message names the input is the answer."""
    calls = [lambda: build('ring', 'x'), lambda: build('ring', np.nan),
             lambda: build('ring', 2), lambda: build('ring', 8, seed='x'),
             lambda: build('ring', 8, seed=-1), lambda: build('ring', 8, a='x'),
             lambda: build('ring', 8, b=1), lambda: build('molecule', 'XYZ'),
             lambda: build('nope'), lambda: MaudCalculator(a=0),
             lambda: MaudCalculator(springs=[[0, 0]]), lambda: MaudCalculator(dim=4),
             lambda: MaudCalculator(backend='cuda')]
    return calls


def main() -> None:
    with tempfile.TemporaryDirectory() as name:
        directory = Path(name)
        classes = [('unchecked run arguments (fmax x steps)', run_arguments()),
                   ('keywords (each x hostile values)', keywords()),
                   ('file arguments', files(directory)),
                   ('stale results at small scales', small_scales()),
                   ('NaN reaching the user', non_finite(directory)),
                   ('overflow at extreme scales (H2)', extreme_scales()),
                   ('FMM near pairs (H2)', fmm_near_pairs()),
                   ('2D scenes under ASE drivers', planar_drivers()),
                   ('unclear errors (builders, calculator)', unclear_errors())]
        print('| class | inputs | correct answer | ValueError | MaudError | other |')
        print('| --- | --- | --- | --- | --- | --- |')
        others = []
        for title, runs in classes:
            counts = Counter()
            for run in runs:
                result = outcome(run)
                counts[result.split(':')[0]] += 1
                if result != 'correct':
                    others.append(f'{title}: {result}')
            print(f'| {title} | {len(runs)} | {counts["correct"]} | {counts["ValueError"]} '
                  f'| {counts["MaudError"]} | {counts["other"]} |', flush=True)
    for line in others:   # every error's message, and the defects
        print(' -', line[:300], file=sys.stderr)


if __name__ == '__main__':
    main()
