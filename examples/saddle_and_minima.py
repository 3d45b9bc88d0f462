"""Saddles and the minima they join, found and classified.

1. The ``cage`` scene: a point inside a fixed ring sits on a saddle whose
   unstable direction shows in its own nodal block. ``Maud(target='stationary')``
   finds it; stepping off along the unstable mode and relaxing with Maud gives
   the two minima on either side.
2. Six points in the plane, every pair sprung: two minima, a pentagon round a
   centre point and, slightly higher, a hexagon with alternate corners at two
   radii. The saddle between them is collective: every nodal block is
   positive definite there, so the specification's nodal step
   (``model='nodal'``) is pushed off it and ends in a minimum. The signed
   Newton step on the whole Hessian, ``Maud(target='stationary',
   model='exact')``, reaches it from a rough guess in a few steps; it is
   classified (index 1), left both ways and the sides relaxed with Maud.

It prints energies and indices and draws the six-point saddle's three lowest
modes in ``saddle_and_minima.png``.

Run: ``python examples/saddle_and_minima.py``
"""

import itertools

import matplotlib
import numpy as np
from ase import Atoms

from ase_maud import Maud, MaudCalculator
from ase_maud.analysis.stationary import classify, displace_along_mode
from ase_maud.scenes.catalogue import build

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402


def guess():
    """A unit pentagon whose sixth point sits 0.6 of the way from the centre
    to the middle of an edge; every pair sprung, in the plane."""
    angles = 2 * np.pi * np.arange(5) / 5
    positions = np.zeros((6, 3))
    positions[:5, 0], positions[:5, 1] = np.cos(angles), np.sin(angles)
    positions[5, :2] = 0.6 * np.cos(np.pi / 5), 0.6 * np.sin(np.pi / 5)
    atoms = Atoms('X6', positions=positions)
    springs = list(itertools.combinations(range(6), 2))
    atoms.calc = MaudCalculator(springs=springs, dim=2)
    return atoms


def stationary(atoms, model, fmax=1e-10):
    """Move ``atoms`` to a nearby stationary point of any index with the
    signed step of ``model``; return its classification."""
    Maud(atoms, target='stationary', model=model, logfile=None).run(fmax=fmax)
    return classify(atoms)


def plot_modes(atoms, point, count, path):
    """Draw the ``count`` lowest modes of ``point`` as arrows on the points."""
    fig, axes = plt.subplots(1, count, figsize=(3.2 * count, 3.4))
    x, y = atoms.positions[:, 0], atoms.positions[:, 1]
    for k, ax in enumerate(axes):
        mode = point.modes[k]
        ax.quiver(x, y, mode[:, 0], mode[:, 1], color='C3', angles='xy',
                  scale_units='xy', scale=1.5)
        ax.plot(x, y, 'o', color='C0')
        ax.set_title(f'mode {k}: $\\lambda$ = {point.eigenvalues[k]:.3f}')
        ax.set_aspect('equal')
        ax.margins(0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def saddle_and_sides(saddle, name):
    """Classify ``saddle``, leave it both ways along its unstable mode,
    relax each side with Maud and print all three."""
    point = classify(saddle)
    print(f'{name}: saddle  E = {saddle.get_potential_energy():.6f}  index '
          f'{point.index} ({point.verdict}, fmax {point.fmax:.1e})')
    assert point.verdict == 'saddle' and point.index == 1
    for side_name, side in zip(('plus', 'minus'),
                               displace_along_mode(saddle, point, step=0.3), strict=True):
        Maud(side, logfile=None).run(fmax=1e-9)
        end = classify(side)
        print(f'{name}: {side_name:6s} E = {side.get_potential_energy():.6f}'
              f'  index {end.index} ({end.verdict})')
    return point


def main():
    cage = build('cage', 8, seed=0)
    stationary(cage, 'exact')
    saddle_and_sides(cage, 'cage')

    nodal = guess()
    end = stationary(nodal, 'nodal', fmax=1e-8)
    print(f'six points: the nodal step from the guess ends in a {end.verdict} '
          f'(E = {nodal.get_potential_energy():.6f}): the saddle is collective')
    six = guess()
    stationary(six, 'exact')
    point = saddle_and_sides(six, 'six points')
    plot_modes(six, point, 3, 'saddle_and_minima.png')
    print('the six-point saddle\'s lowest modes are in saddle_and_minima.png')


if __name__ == '__main__':
    main()
