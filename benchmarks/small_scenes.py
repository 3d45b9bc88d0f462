"""Small scenes at the speed of their arithmetic: Maud against ASE's optimizers and
SciPy's L-BFGS-B, in calls and CPU seconds, with a profile of a Maud step.

Independent small scenes (clusters, rings, trees, nets, random graphs and a wheel of 10-60
points, seeds no test or tuning used), each relaxed to ``--fmax`` from the same start by:

- ``Maud`` (its defaults, as users call it; no log);
- ASE's ``BFGS``, ``LBFGS`` and ``FIRE`` (calls only: the best of them is the call baseline);
- ``L-BFGS-B (ASE)``: SciPy's L-BFGS-B on the same ASE calculator
  (:class:`ase_maud.bench.optimizers.ScipyLBFGSB`);
- ``L-BFGS-B (arrays)``: SciPy's L-BFGS-B on the potential's arrays directly (the exact
  numba sum and the springs in reduced units, no ASE object in the loop): the floor of the
  numerics.

Calls are energy-and-forces evaluations (Maud's are Hessian evaluations too: each step's
one calculator call gives the energy, forces and Hessian together). CPU seconds are the
process's (``time.process_time``), after every kernel was compiled and run once, the median
of ``--repeat`` runs from fresh copies (default 3; the calls are the same each time). Every end
point is checked to be a minimum by the analytic Hessian
(``ase_maud.analysis.stationary.classify``).
``--profile`` gives Maud's CPU a step and a start (the optimiser's construction and
first evaluation), and their shares in the kernel (the Hessian, or a held net's block of
it), the factorisations of the Python step and the compiled step, of a whole run and of
its steps alone (timers around those calls over repeated unprofiled runs of one scene;
it runs on an older checkout too).
Run with one thread and save the raw numbers::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/small_scenes.py --out small-scenes.csv --profile

On a shared machine one pass's CPU varies by tens of per cent: ``--pool pass1.csv
pass2.csv ...`` takes each run's CPU as its median over several passes' CSVs and prints
the ratios and a table of medians over the seeds (no run).
"""

from __future__ import annotations

import argparse
import csv
import time
from contextlib import contextmanager

import numpy as np
from ase.optimize import BFGS, FIRE, LBFGS
from scipy.optimize import minimize

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.backends import direct
from ase_maud.bench.optimizers import ScipyLBFGSB
from ase_maud.counting import CallRecorder
from ase_maud.optimize.models import exact as stiffness

try:   # a checkout with the compiled step (older ones run without it)
    from ase_maud.optimize import compiled_step as compiled
except ImportError:
    compiled = None
from ase_maud.physics import pair_law
from ase_maud.physics.pair_law import spring_terms
from ase_maud.scenes.catalogue import build

#: (scene, size) of the suite; the seeds are ``--seeds``.
SCENES = [('all_pairs', 12), ('all_pairs', 30), ('all_pairs2d', 20), ('ring', 40),
          ('tree', 30), ('tree', 60), ('random_graph', 40), ('wheel', 16),
          ('net2d', 5), ('hanging_net', 5)]
ASE = {'BFGS': BFGS, 'LBFGS': LBFGS, 'FIRE': FIRE}


def fresh(atoms):
    copy = atoms.copy()
    copy.calc = type(atoms.calc)(**atoms.calc.parameters)
    return copy


def run_maud(atoms, fmax, steps):
    with CallRecorder(atoms.calc) as recorder:
        start = time.process_time()
        with Maud(atoms, logfile=None) as opt:
            converged = opt.run(fmax=fmax, steps=steps)
        cpu = time.process_time() - start
    return converged, len(recorder.samples), cpu


def run_ase(name, atoms, fmax, steps):
    with CallRecorder(atoms.calc) as recorder:
        start = time.process_time()
        converged = ASE[name](atoms, logfile=None).run(fmax=fmax, steps=steps)
        cpu = time.process_time() - start
    return converged, len(recorder.samples), cpu


def run_lbfgsb(atoms, fmax, steps):
    with CallRecorder(atoms.calc) as recorder:
        start = time.process_time()
        converged = ScipyLBFGSB(atoms).run(fmax=fmax, steps=steps)
        cpu = time.process_time() - start
    return converged, len(recorder.samples), cpu


def run_arrays(atoms, fmax, steps):
    """L-BFGS-B on the potential's arrays: the exact sum and the springs,
    the free coordinates only (no scene of the suite has loads or fixed
    points but the nets, whose fixed points are held by a mask)."""
    potential = atoms.calc.potential
    free = np.ones((len(atoms), 3), bool)
    mask = free.astype(float)
    for constraint in atoms.constraints:
        constraint.adjust_forces(atoms, mask)
    free = mask != 0
    if potential.dim == 2:
        free[:, 2] = False
    x0 = atoms.positions.copy()
    calls = [0]

    class Converged(Exception):
        pass

    def energy_gradient(v):
        calls[0] += 1
        x = x0.copy()
        x[free] = v
        scaled = potential.reduced(x)
        e_rep, f_rep, _ = direct.evaluate(scaled)
        e_spr, f_spr = spring_terms(scaled, potential.springs, potential.stiffnesses)
        forces = potential.force_unit * (f_rep + f_spr)
        if potential.loads is not None:
            forces += potential.loads
        forces[~free] = 0.0
        if np.sqrt((forces**2).sum(axis=1).max()) <= fmax:
            x0[free] = v
            raise Converged
        energy = potential.energy_unit * (e_rep + e_spr)
        if potential.loads is not None:
            energy -= np.vdot(potential.loads, x)
        return energy, -forces[free]

    start = time.process_time()
    try:
        minimize(energy_gradient, x0[free], jac=True, method='L-BFGS-B',
                 options={'maxiter': steps, 'maxfun': 100 * steps, 'ftol': 0.0, 'gtol': 0.0})
        converged = False
    except Converged:
        converged = True
    return converged, calls[0], time.process_time() - start


def repeated(runner, atoms, fmax, steps, repeat, relaxed=None):
    """``runner``'s (converged, calls, CPU seconds) from ``atoms``: the first
    run's convergence and calls (every run makes the same), the median CPU of
    ``repeat`` runs, each from a fresh copy (the first into ``relaxed`` if
    given): one run's CPU varies by tens of per cent on a busy machine."""
    runs = [runner(relaxed if relaxed is not None and k == 0 else fresh(atoms), fmax, steps)
            for k in range(repeat)]
    return runs[0][0], runs[0][1], float(np.median([cpu for _, _, cpu in runs]))


def measure(name, size, seed, fmax, steps, repeat=3):
    """One scene's row: calls and CPU of every optimiser (CPU the median of
    ``repeat`` runs), and Maud's verdict."""
    atoms = build(name, size, seed=seed)
    row = {'scene': f'{name}:{size}', 'seed': seed, 'points': len(atoms)}
    relaxed = fresh(atoms)
    ok, calls, cpu = repeated(run_maud, atoms, fmax, steps, repeat, relaxed)
    row.update({'Maud calls': calls, 'Maud CPU s': cpu, 'Maud converged': ok,
                'Maud verdict': classify(relaxed).verdict if ok else 'not converged'})
    for label, runner in (('L-BFGS-B (ASE)', run_lbfgsb), ('L-BFGS-B (arrays)', run_arrays)):
        ok, calls, cpu = repeated(runner, atoms, fmax, steps, repeat)
        row.update({f'{label} calls': calls, f'{label} CPU s': cpu,
                    f'{label} converged': ok})
    for label in ASE:
        ok, calls, _ = run_ase(label, fresh(atoms), fmax, steps)
        row[f'{label} calls'] = calls if ok else np.inf
    row['best ASE calls'] = min(row[f'{label} calls'] for label in ASE)
    row['CPU / L-BFGS-B (ASE)'] = row['Maud CPU s'] / row['L-BFGS-B (ASE) CPU s']
    row['CPU / L-BFGS-B (arrays)'] = row['Maud CPU s'] / row['L-BFGS-B (arrays) CPU s']
    row['calls / best ASE'] = row['Maud calls'] / row['best ASE calls']
    return row


@contextmanager
def timed(module, names, totals, key):
    """Within: each function ``names`` of ``module`` (those it has: an older
    version may lack one, or the module: None) adds its process CPU seconds to ``totals[key]``
    (restored after)."""
    kept = {name: getattr(module, name) for name in names
            if module is not None and hasattr(module, name)}

    def timer(function):
        def wrapper(*args, **kwargs):
            start = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                totals[key] += time.process_time() - start
        return wrapper

    for name, function in kept.items():
        setattr(module, name, timer(function))
    try:
        yield
    finally:
        for name, function in kept.items():
            setattr(module, name, function)


def _timed(copies, fmax, steps):
    """Maud's runs of at most ``steps`` steps on ``copies``: the process CPU of
    all, of the kernel, the factorisations and the compiled step (timers
    around those calls, :func:`profile`), and the steps made."""
    totals = {'kernel': 0.0, 'factorisations': 0.0, 'compiled step': 0.0}
    made = 0
    with timed(direct, ['repulsion_hessian', 'repulsion_hessian_block'], totals, 'kernel'), \
            timed(pair_law, ['repulsion_hessian_block'], totals, 'kernel'), \
            timed(compiled, ['scene_terms'], totals, 'kernel'), \
            timed(compiled, ['_judge', '_move'], totals, 'compiled step'), \
            timed(stiffness, ['dpotrf', 'dpotrs', 'dsyevd'], totals, 'factorisations'):
        start = time.process_time()
        for copy in copies:
            with Maud(copy, logfile=None) as opt:
                opt.run(fmax=fmax, steps=steps)
            made += opt.nsteps
        total = time.process_time() - start
    return total, totals, made


def profile(name, size, seed, fmax, repeats=20):
    """Shares of Maud's CPU (process CPU) in the kernel (the one pass over
    the pairs that gives the energy, forces and Hessian), the factorisations
    (LAPACK's Cholesky and eigen-decomposition as the exact model calls
    them: the Python step's, and the compiled step's eigen-decompositions),
    the compiled step (its merit test, Cholesky factor, solves and trust
    region, where a checkout has it) and the rest, by timers around those
    calls in ``repeats`` unprofiled runs (cProfile's cost per Python call
    would inflate the rest): of a whole run (the optimiser's construction
    and first evaluation included), and of its steps alone (the same runs
    less as many stopped before their first step)."""
    atoms = build(name, size, seed=seed)
    run_maud(fresh(atoms), fmax, 5000)   # every kernel compiled and loaded
    total, totals, steps = _timed([fresh(atoms) for _ in range(repeats)], fmax, 5000)
    start, at_start, _ = _timed([fresh(atoms) for _ in range(repeats)], fmax, 0)
    row = {'scene': f'{name}:{size}', 'seed': seed, 'us a step': 1e6 * total / steps,
           'us a start': 1e6 * start / repeats}
    for label, cpu, parts in (('run', total, totals), ('step', total - start, {
            key: totals[key] - at_start[key] for key in totals})):
        row.update({f'{key} ({label})': value / cpu for key, value in parts.items()})
        row[f'rest ({label})'] = 1 - sum(parts.values()) / cpu
    return row


def pool(paths: list[str]) -> None:
    """Print the ratios to L-BFGS-B (ASE) of the passes in the CSVs ``paths``
    (this script's, the same seeds), each run's CPU the median over the passes,
    and per scene the medians over the seeds."""
    passes = []
    for path in paths:
        with open(path, newline='') as handle:
            passes.append(list(csv.DictReader(handle)))
    rows = passes[0]
    for path, runs in zip(paths, passes, strict=True):
        if [(r['scene'], r['seed']) for r in runs] != [(r['scene'], r['seed']) for r in rows]:
            raise SystemExit(f'{path}: other scenes or seeds than {paths[0]}: not passes '
                             'of one suite')
    cpu = {name: np.median([[float(row[f'{name} CPU s']) for row in runs] for runs in passes],
                           axis=0) for name in ('Maud', 'L-BFGS-B (ASE)')}
    ratio = cpu['Maud'] / cpu['L-BFGS-B (ASE)']
    print(f'{len(paths)} passes, CPU / L-BFGS-B (ASE): median {np.median(ratio):.3f}, worst '
          f'{ratio.max():.3f}, above 0.5: {int((ratio > 0.5).sum())} of {len(ratio)}')
    print('scene | points | Maud calls | Maud ms | L-BFGS-B calls | L-BFGS-B ms | BFGS calls '
          '| FIRE calls | CPU x L-BFGS-B')
    for scene in dict.fromkeys(row['scene'] for row in rows):
        runs = [k for k, row in enumerate(rows) if row['scene'] == scene]
        medians = {name: np.median([float(rows[k][f'{name} calls']) for k in runs])
                   for name in ('Maud', 'L-BFGS-B (ASE)', 'BFGS', 'FIRE')}
        calls = {name: f'{value:.0f}' if np.isfinite(value) else 'not converged'
                 for name, value in medians.items()}
        ms = {name: f'{1e3 * np.median(cpu[name][runs]):.1f}' for name in cpu}
        print(' | '.join([scene, rows[runs[0]]['points'], calls['Maud'], ms['Maud'],
                          calls['L-BFGS-B (ASE)'], ms['L-BFGS-B (ASE)'], calls['BFGS'],
                          calls['FIRE'], f'{np.median(ratio[runs]):.2f}']))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[101, 102, 103])
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--out', default=None, help='CSV file of the raw numbers')
    parser.add_argument('--profile', action='store_true')
    parser.add_argument('--repeat', type=int, default=3,
                        help='runs of each optimiser whose median CPU is reported')
    parser.add_argument('--pool', nargs='+', metavar='CSV',
                        help='pool the passes in these CSVs (module docstring) and stop')
    args = parser.parse_args()
    if args.pool:
        pool(args.pool)
        return
    for name, size in SCENES[:3]:   # compile and warm every kernel
        measure(name, size, 0, 1e-2, 50, 1)
    rows = [measure(name, size, seed, args.fmax, args.steps, args.repeat)
            for seed in args.seeds for name, size in SCENES]
    columns = ['scene', 'seed', 'points', 'Maud calls', 'Maud CPU s', 'Maud verdict',
               'best ASE calls', 'L-BFGS-B (ASE) calls', 'L-BFGS-B (ASE) CPU s',
               'L-BFGS-B (arrays) calls', 'L-BFGS-B (arrays) CPU s', 'calls / best ASE',
               'CPU / L-BFGS-B (ASE)', 'CPU / L-BFGS-B (arrays)']
    print(' | '.join(columns))
    for row in rows:
        print(' | '.join(f'{row[c]:.3g}' if isinstance(row[c], float) else str(row[c])
                         for c in columns))
    for ratio in ('calls / best ASE', 'CPU / L-BFGS-B (ASE)', 'CPU / L-BFGS-B (arrays)'):
        values = [row[ratio] for row in rows]
        print(f'{ratio}: median {np.median(values):.3f}, worst {max(values):.3f}')
    print('minima verified:', sum(row['Maud verdict'] == 'minimum' for row in rows),
          'of', len(rows))
    if args.out:
        with open(args.out, 'x', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    if args.profile:
        for name, size in (('all_pairs', 12), ('random_graph', 40), ('all_pairs', 30),
                           ('hanging_net', 5)):
            shares = profile(name, size, args.seeds[0], args.fmax)
            print('profile', shares['scene'], f"{shares['us a step']:.0f} us a step, "
                  f"{shares['us a start']:.0f} us a start; shares of", '; '.join(
                      f'{label}: ' + ' '.join(f'{key} {shares[f"{key} ({label})"]:.0%}' for key in
                                               ('kernel', 'factorisations', 'compiled step',
                                                'rest'))
                      for label in ('run', 'step')))


if __name__ == '__main__':
    main()
