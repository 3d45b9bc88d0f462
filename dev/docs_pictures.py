"""Draw the pictures of the documentation site into ``docs/img/``.

Every PNG the docs show is written here, from seeded scenes, so that anyone can draw
them again (and check them) with::

    NUMBA_NUM_THREADS=1 python dev/docs_pictures.py [--out docs/img] [NAME ...]

Names: ``hanging_net`` (the default scene of ``ase-maud relax``, start and relaxed),
``steps`` (fmax against calculator calls of Maud's stiffness models and of ASE's FIRE
and LBFGS on one net), ``saddle_and_minima`` (the picture ``examples/saddle_and_minima.py``
draws, run in a scratch directory) and ``net_mode`` (the lowest modes of a relaxed
``net2d``, as ``examples/classify_large_net.py`` finds them, on a small net). Each is
stored as a palette PNG of at most 64 colours, to keep the repository small.
"""

from __future__ import annotations

import argparse
import os
import runpy
import tempfile
from collections.abc import Callable
from pathlib import Path

import matplotlib
import numpy as np
from ase.optimize import FIRE, LBFGS
from matplotlib.colors import Normalize
from PIL import Image

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import CallRecorder
from ase_maud.form.pictures import COLOURS as SPRING_COLOURS
from ase_maud.form.pictures import draw, orient, spring_values
from ase_maud.scenes.catalogue import build

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: Colours kept in each palette PNG.
COLOURS = 64
DPI = 90


def save(fig: plt.Figure | None, path: Path, source: Path | None = None) -> None:
    """Write ``fig`` (or the PNG at ``source``) to ``path`` as a palette PNG."""
    if fig is not None:
        source = path.with_suffix('.rgba.png')
        fig.savefig(source, dpi=DPI)
        plt.close(fig)
    image = Image.open(source).convert('RGB')
    image.quantize(colors=COLOURS, method=Image.Quantize.MEDIANCUT).save(path, optimize=True)
    if fig is not None:
        source.unlink()
    print(f'{path}: {path.stat().st_size / 1024:.0f} kB')


def hanging_net(out: Path) -> None:
    """The default scene of ``ase-maud relax`` before and after Maud, drawn as
    ``ase-maud show`` draws a net (:func:`ase_maud.form.pictures.draw`)."""
    start, atoms = (build('hanging_net', 12, seed=0) for _ in range(2))
    with Maud(atoms, logfile=None) as opt:
        opt.run(fmax=1e-6)
    forces = np.concatenate([spring_values(a, 'force') for a in (start, atoms)])
    norm = Normalize(forces.min(), forces.max())   # one colour scale for both
    fig = plt.figure(figsize=(9, 4.4))
    axes = [fig.add_subplot(1, 2, k, projection='3d') for k in (1, 2)]
    for ax in axes:
        orient(ax, 'iso')
    draw(axes[0], start, norm=norm, title=f'start: E = {start.get_potential_energy():.6g}')
    lines = draw(axes[1], atoms, norm=norm, ftol=1e-6, title=f'after {opt.nsteps} Maud '
                 f'steps: E = {atoms.get_potential_energy():.6g}, converged')
    fig.tight_layout()
    fig.colorbar(lines, ax=axes, shrink=0.6, label=SPRING_COLOURS['force'])
    save(fig, out / 'hanging_net.png')


def steps(out: Path) -> None:
    """fmax against calculator calls on a 12 x 12 hanging net, one run each."""
    runs = {'Maud (auto: exact here)': (Maud, {}),
            "Maud model='global'": (Maud, {'model': 'global'}),
            "Maud model='nodal' (the specification's step)": (Maud, {'model': 'nodal'}),
            'FIRE': (FIRE, {}), 'LBFGS': (LBFGS, {})}
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    for (label, (optimizer, kwargs)), style in zip(runs.items(), ('-', '--', '-.', '-', '-'),
                                                   strict=True):
        atoms = build('hanging_net', 12, seed=0)
        with CallRecorder(atoms.calc) as recorder, \
                optimizer(atoms, logfile=None, **kwargs) as opt:
            opt.run(fmax=1e-6, steps=3000)
        calls, fmax = np.array(recorder.samples)[:, [0, 3]].T
        ax.semilogy(calls, np.minimum.accumulate(fmax), style, label=label)
    ax.set_ylim(1e-7, None)
    ax.set_xlabel('calculator calls')
    ax.set_ylabel('lowest fmax so far ($Q a$)')
    ax.set_title('hanging_net 12 (144 points, boundary fixed), seed 0', fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save(fig, out / 'steps.png')


def saddle_and_minima(out: Path) -> None:
    """Run ``examples/saddle_and_minima.py`` in a scratch directory; keep its PNG."""
    here = Path.cwd()
    with tempfile.TemporaryDirectory() as scratch:
        os.chdir(scratch)
        try:
            runpy.run_path(str(ROOT / 'examples' / 'saddle_and_minima.py'),
                           run_name='__main__')
        finally:
            os.chdir(here)
        save(None, out / 'saddle_and_minima.png',
             source=Path(scratch) / 'saddle_and_minima.png')


def net_mode(out: Path) -> None:
    """The three lowest modes of a relaxed 12 x 12 ``net2d``, from the iterative
    classification of ``examples/classify_large_net.py``."""
    atoms = build('net2d', 12, seed=0)
    with Maud(atoms, logfile=None) as opt:
        opt.run(fmax=1e-6)
    point = classify(atoms, method='iterative', k=3, ftol=1e-5)
    fig, axes = plt.subplots(1, 3, figsize=(8.4, 3.0))
    x, y = atoms.positions[:, 0], atoms.positions[:, 1]
    for k, ax in enumerate(axes):
        mode = point.modes[k]
        for i, j in atoms.calc.parameters['springs']:
            ax.plot(x[[i, j]], y[[i, j]], color='0.75', lw=0.6)
        ax.plot(x, y, '.', color='C0', ms=3)
        longest = np.linalg.norm(mode, axis=1).max()
        ax.quiver(x, y, mode[:, 0], mode[:, 1], color='C3', angles='xy',
                  scale_units='xy', scale=longest / 0.9, width=0.006)
        ax.set_title(f'{point.verdict}, mode {k}: $\\lambda$ = '
                     f'{point.eigenvalues[k]:.3g} $Q$', fontsize=9)
        ax.set_aspect('equal')
        ax.set_axis_off()
    fig.tight_layout()
    save(fig, out / 'net_mode.png')


PICTURES: dict[str, Callable[[Path], None]] = {
    f.__name__: f for f in (hanging_net, steps, saddle_and_minima, net_mode)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('names', nargs='*', metavar='NAME',
                        help=f'of: {", ".join(PICTURES)} (default: all)')
    parser.add_argument('--out', type=Path, default=ROOT / 'docs' / 'img')
    args = parser.parse_args()
    unknown = sorted(set(args.names) - set(PICTURES))
    if unknown:
        parser.error(f'unknown pictures {unknown}; known: {", ".join(PICTURES)}')
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.names or PICTURES:
        PICTURES[name](args.out)


if __name__ == '__main__':
    main()
