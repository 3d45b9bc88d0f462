"""Measure the numbers of docs/hard_cases.md: Maud's outcome and steps on
every hard case, several seeds each. One line per run; run with one thread:

    NUMBA_NUM_THREADS=1 python dev/hard_cases_table.py [--dense 100 200 300]
"""

import argparse
import io
import time

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.optimize import BFGS, FIRE

from ase_maud import Maud, MaudCalculator, MaudError
from ase_maud.physics.topology import fixed_atoms
from ase_maud.scenes import hard_cases as hc
from ase_maud.scenes.catalogue import build

SEEDS = (0, 1, 2)


def relax(atoms, fmax=1e-8, steps=30000, opt=Maud, **kwargs):
    """(outcome, steps, seconds, energy) of a run of ``opt`` (Maud); outcome
    is 'converged' or the name of the MaudError raised. Maud runs the
    specification's nodal step (the catalogue's subject) unless ``model`` is
    given."""
    if opt is Maud:
        kwargs.setdefault('model', 'nodal')
    log = io.StringIO()
    start = time.perf_counter()
    with opt(atoms, logfile=log, **kwargs) as dyn:
        try:
            outcome = 'converged' if dyn.run(fmax=fmax, steps=steps) else 'not converged'
        except MaudError as error:
            outcome = type(error).__name__
    return outcome, dyn.nsteps, time.perf_counter() - start, atoms.get_potential_energy()


def show(case, atoms, hessian=False, **kwargs):
    """Print one run; with ``hessian``, the lowest eigenvalues of the Hessian
    over the free atoms at its end."""
    outcome, steps, seconds, energy = relax(atoms, **kwargs)
    name = kwargs.get('opt', Maud).__name__
    lowest = ''
    if hessian:
        free = np.repeat(~fixed_atoms(atoms), 3)
        h = atoms.calc.get_hessian(atoms)[np.ix_(free, free)]
        eig = np.linalg.eigvalsh(h)
        lowest = (f' negative {np.sum(eig < -1e-6)}, lowest {eig[0]:.3g}, '
                  f'lowest above 1e-9 {eig[eig > 1e-9][0]:.3g}, '
                  f'highest {eig[-1]:.3g}')
    print(f'{case:40s} {name:5s} {outcome:30s} {steps:6d} steps '
          f'{seconds:7.2f} s E = {energy:.10f}{lowest}', flush=True)


def shrink(atoms, factor):
    centre = atoms.positions.mean(axis=0)
    atoms.positions = centre + factor * (atoms.positions - centre)
    return atoms


def dimer(length):
    atoms = Atoms('H2', positions=[[-length / 2, 0, 0], [length / 2, 0, 0]])
    atoms.calc = MaudCalculator([(0, 1)])
    return atoms


def islands_apart(gap):
    atoms = hc.islands(2, seed=0)
    atoms.positions[hc.ISLAND:, 0] += gap - 3.0
    return atoms


def singly_anchored(seed):
    atoms = hc.anchored_islands(3, seed=seed)
    atoms.set_constraint(FixAtoms(indices=[0, hc.ISLAND, 2 * hc.ISLAND]))
    return atoms


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--dense', type=int, nargs='*', default=[60, 100],
                        help='sizes of the dense all_pairs clusters')
    args = parser.parse_args()
    for s in SEEDS:
        show(f'close_pair(8) seed {s}', hc.close_pair(8, seed=s))
        show(f'all_pairs(8) seed {s}', build('all_pairs', 8, seed=s))
    for length in (1.2, 2.0, 3.0, 1e6):
        show(f'symmetric dimer L = {length:g}', dimer(length))
    for s in SEEDS:
        show(f'loose_point(6) seed {s}', hc.loose_point(6, seed=s))
        show(f'bead(8) seed {s}', hc.bead(8, seed=s), fmax=1e-10)
        show(f'ring_with_centre(16) seed {s}', hc.ring_with_centre(16, seed=s))
        show(f'ring_with_centre(16) x0.3 seed {s}',
             shrink(hc.ring_with_centre(16, seed=s), 0.3))
    for n in (2, 10, 50, 100):
        show(f'no_springs({n})', hc.no_springs(n, seed=1))
    for k in (2, 3, 4, 6):
        show(f'islands({k})', hc.islands(k, seed=1))
    for gap in (3, 10, 30, 100):
        show(f'two islands {gap} a apart', islands_apart(gap))
    for s in SEEDS:
        for opt in (Maud, FIRE, BFGS):
            show(f'anchored_islands(3) seed {s}', hc.anchored_islands(3, seed=s),
                 opt=opt)
    for s in (3, 0):
        show(f'singly anchored islands seed {s}', singly_anchored(s), fmax=1e-6,
             hessian=True)
    for name, size in (('hanging_net', 5), ('ring', 12), ('random_graph', 12),
                       ('all_pairs', 8), ('chain', 12)):
        for a, q in ((1, 1), (1e-6, 1e-9), (1e-6, 1e9), (1e6, 1e-9), (1e6, 1e9)):
            show(f'{name}({size}) a={a:g} Q={q:g}',
                 build(name, size, seed=3, a=a, Q=q), fmax=1e-8 * a * q)
    for n in (10, 20, 40):
        show(f'stiff_soft({n})', hc.stiff_soft(n, seed=0), fmax=1e-6)
        show(f'stiff_soft({n}) scalar', hc.stiff_soft(n, seed=0), fmax=1e-6,
             method='scalar')
        for opt in (FIRE, BFGS):
            show(f'stiff_soft({n})', hc.stiff_soft(n, seed=0), fmax=1e-6,
                 steps=20000, opt=opt)
    show('stiff_soft(20), 20-point cluster', hc.stiff_soft(20, seed=0, dense=20),
         fmax=1e-6)
    for n in (25, 50, 100, 150, 200):
        show(f'chain({n}) seed 1', build('chain', n, seed=1), fmax=1e-6)
    for s in SEEDS:
        show(f'flat_cluster(8) seed {s}', hc.flat_cluster(8, seed=s),
             hessian=True)
    for s in SEEDS:
        show(f'tangled_net(6) seed {s}', hc.tangled_net(6, seed=s))
        show(f'tangled_hanging_net(6) seed {s}', hc.tangled_hanging_net(6, seed=s))
    for s in (0, 1, 2, 3):
        show(f'tangled_hanging_net(10) seed {s}', hc.tangled_hanging_net(10, seed=s))
    for opt in (FIRE, BFGS):
        show('tangled_hanging_net(10) seed 3', hc.tangled_hanging_net(10, seed=3),
             opt=opt)
    for name, size in (('ring', 16), ('all_pairs', 8)):
        for factor in (1, 1e-6, 1e6):
            for s in (4, 5):
                show(f'{name}({size}) x{factor:g} seed {s}',
                     shrink(build(name, size, seed=s), factor))
    for name, size in (('ring', 16), ('all_pairs', 10), ('hanging_net', 6),
                       ('random_graph', 20), ('chain', 20)):
        for patience in (2000, 200):
            show(f'{name}({size}) fmax 1e-15 patience {patience}',
                 build(name, size, seed=0), fmax=1e-15, patience=patience)
    for n in args.dense:
        show(f'all_pairs({n})', build('all_pairs', n, seed=0), fmax=1e-6)


if __name__ == '__main__':
    main()
