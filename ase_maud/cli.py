"""The ``ase-maud`` command (also ``python -m ase_maud``).

- ``ase-maud relax``: relax a built-in scene with Maud, ASE's log on stdout
  and a trajectory for ``ase gui``.
- ``ase-maud bench``: every chosen optimiser from the same starts, force
  calls and wall time against the error; CSV, markdown and PNG in ``--out``.
- ``ase-maud backends``: time per call against accuracy of the registered
  backends (:mod:`ase_maud.backends`).

``--threads N`` pins OpenMP, BLAS and numba to N threads
(:func:`ase_maud.threads.pin_threads`); if BLAS may already run with another
count, the command starts itself again with them set (or, when
``main(argv)`` is called from Python, warns). This module only parses
arguments and calls the library; each command imports what it needs when it
runs (relax needs no matplotlib).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .threads import pin_threads


def _size(text):
    """A scene size: an int if it reads as one, else the text ('C6H6')."""
    try:
        return int(text)
    except ValueError:
        return text


def relax(args: argparse.Namespace) -> int:
    """``ase-maud relax``: exit status 0 if converged, else 1."""
    from . import kernels_cached
    from .bench.runner import CallRecorder
    from .optimizer import Maud
    from .scenes import build

    if not kernels_cached():
        print('compiling the kernels (first run only, ~20 s)...', file=sys.stderr,
              flush=True)
    atoms = build(args.scene, args.size, seed=args.seed)
    with CallRecorder(atoms.calc) as recorder, \
            Maud(atoms, model=args.model, method=args.method, logfile='-',
                 trajectory=args.traj) as opt:
        converged = opt.run(fmax=args.fmax, steps=args.steps)
    fmax = (atoms.get_forces()**2).sum(axis=1).max() ** 0.5
    print(f'{"converged" if converged else "NOT converged"}: {args.scene} '
          f'{len(atoms)} points, {opt.nsteps} steps, '
          f'{len(recorder.samples)} force calls, energy '
          f'{atoms.get_potential_energy():.12g}, fmax {fmax:.3g}; '
          f'trajectory {args.traj}')
    return 0 if converged else 1


def bench(args: argparse.Namespace) -> int:
    """``ase-maud bench``: exit status 0, or 130 if interrupted."""
    from .bench.suite import benchmark
    from .scenes import SUITES, scene_sizes

    starts = [(scene, size, seed)
              for scene, size in scene_sizes(args.scenes, args.sizes, SUITES[args.suite])
              for seed in args.seeds]
    show = sys.stderr.isatty() if args.progress is None else args.progress
    interrupted = benchmark(
        starts, args.optimizers, Path(args.out), levels=args.fmax, steps=args.steps,
        reference=args.reference, ref_fmax=args.ref_fmax,
        energy_rtol=args.energy_rtol, progress=show, argv=args.argv)
    print(f'results in {args.out}/')
    return 130 if interrupted else 0


def backends(args: argparse.Namespace) -> int:
    """``ase-maud backends``: exit status 0."""
    from .bench.backends import write_backends_report

    print(write_backends_report(Path(args.out), args.natoms, args.backends,
                                repeats=args.repeats, seed=args.seed,
                                argv=args.argv))
    print(f'results in {args.out}/')
    return 0


def _add_threads(parser, default, default_text):
    parser.add_argument('--threads', type=int, default=default, metavar='N',
                        help='pin OpenMP, BLAS and numba to N threads '
                        f'(default: {default_text})')


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of ``ase-maud`` and its three commands."""
    from . import backends as registry
    from .bench.optimizers import OPTIMIZERS
    from .scenes import SCENES, SUITES
    from .stiffness import METHODS, MODELS

    parser = argparse.ArgumentParser(
        prog='ase-maud', description='The Maud algorithm for points that '
        'repel and are tied by springs: relax a scene, or benchmark.')
    commands = parser.add_subparsers(dest='command', metavar='COMMAND')

    p = commands.add_parser(
        'relax', help='relax a built-in scene with Maud',
        description='Relax a built-in scene with Maud, printing ASE\'s log, '
        'write a trajectory for "ase gui" and a one-line summary.')
    p.add_argument('--scene', default='hanging_net', choices=SCENES,
                   metavar='NAME', help=f'of: {", ".join(SCENES)} '
                   '(default: %(default)s)')
    p.add_argument('--size', type=_size, help="scene size (default: the "
                   "builder's; molecule takes a name such as C6H6)")
    p.add_argument('--seed', type=int, default=0,
                   help='seed of the start (default: %(default)s)')
    p.add_argument('--model', default='auto',
                   choices=('auto', *MODELS),
                   help='stiffness model of the step (default: %(default)s)')
    p.add_argument('--method', default='tensor', choices=METHODS,
                   help='nodal Maud step (default: %(default)s)')
    p.add_argument('--fmax', type=float, default=1e-3,
                   help='largest atomic force norm at convergence '
                   '(default: %(default)s)')
    p.add_argument('--steps', type=int, default=1000,
                   help='step budget (default: %(default)s)')
    p.add_argument('--traj', default='maud.traj',
                   help='trajectory file (default: %(default)s)')
    _add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=relax)

    p = commands.add_parser(
        'bench', help='force calls and wall time against error, per optimiser',
        description='Run every optimiser from the same starts (scene, size, '
        'seed), sampling fmax, energy, force calls, wall and CPU time at '
        'every calculator call; the energy error is against the lowest energy '
        'of a tight reference run. Writes samples.csv (one row per sample), '
        'runs.csv, summary.csv and summary.md (calls and times to each fmax '
        'level, their ratio to the best ASE optimiser and, for CPU time, to '
        'L-BFGS-B), overall.csv (median and worst ratios), and log-log PNGs '
        'of fmax and energy error against calls and time. Ctrl-C stops and '
        'reports what finished.')
    p.add_argument('--scenes', nargs='+', choices=SCENES, metavar='NAME',
                   help=f'of: {", ".join(SCENES)} (default: those of '
                   'the suite, at their suite sizes)')
    p.add_argument('--suite', choices=SUITES, default='small',
                   help='scenes.SUITE (small: under 60 points) or scenes.LARGE '
                   '(large: collective modes, 40 to 2500 points) '
                   '(default: %(default)s)')
    p.add_argument('--sizes', nargs='+', type=_size, metavar='SIZE',
                   help='sizes of every scene (default: suite sizes)')
    p.add_argument('--seeds', nargs='+', type=int, default=[0], metavar='K',
                   help='seeds of the starts (default: 0)')
    p.add_argument('--optimizers', nargs='+', choices=OPTIMIZERS,
                   default=list(OPTIMIZERS), metavar='NAME',
                   help=f'of: {", ".join(OPTIMIZERS)} (default: all)')
    p.add_argument('--fmax', nargs='+', type=float, default=[1e-3, 1e-6],
                   help='fmax levels of the summary; runs stop at the lowest '
                   '(default: 1e-3 1e-6)')
    p.add_argument('--steps', type=int, default=10000,
                   help='step budget of every run (default: %(default)s)')
    p.add_argument('--reference', choices=OPTIMIZERS, default='LBFGS',
                   metavar='NAME', help='optimiser of the reference runs '
                   '(default: %(default)s)')
    p.add_argument('--ref-fmax', type=float, default=1e-9,
                   help='fmax of the reference runs (default: %(default)s)')
    p.add_argument('--energy-rtol', type=float, default=1e-6,
                   help='relative energy difference from the reference '
                   'beyond which a converged run is in another minimum '
                   '(default: %(default)s)')
    p.add_argument('--out', default='maud-bench',
                   help='output directory (default: %(default)s)')
    p.add_argument('--progress', action=argparse.BooleanOptionalAction,
                   help='progress bar on stderr (default: if it is a tty)')
    _add_threads(p, 1, '1')
    p.set_defaults(func=bench)

    p = commands.add_parser(
        'backends',
        help='time per call against accuracy of the calculator backends',
        description='Time one energy-and-forces call, and one call with the '
        'nodal stiffness, of every backend on N random points, and its '
        'relative error against the numpy reference. Writes backends.csv, '
        'backends.md and backends.png.')
    p.add_argument('--natoms', nargs='+', type=int,
                   default=[100, 300, 1000, 3000], metavar='N',
                   help='numbers of points (default: 100 300 1000 3000)')
    needs = '; '.join(f'{b.name} needs {", ".join(b.requires)}'
                      for b in map(registry.get, registry.names())
                      if b.requires)
    p.add_argument('--backends', nargs='+', choices=registry.names(),
                   default=registry.installed(), metavar='NAME',
                   help=f'of: {", ".join(registry.names())} (default: all '
                   f'that are installed; {needs})')
    p.add_argument('--repeats', type=int, default=3,
                   help='timed calls per point, the best kept '
                   '(default: %(default)s)')
    p.add_argument('--seed', type=int, default=0,
                   help='seed of the points (default: %(default)s)')
    p.add_argument('--out', default='maud-bench',
                   help='output directory (default: %(default)s)')
    _add_threads(p, 1, '1')
    p.set_defaults(func=backends)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ase-maud`` on ``argv`` (default ``sys.argv[1:]``); return the
    exit status. Without a command, print the help."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    args.argv = sys.argv[1:] if argv is None else list(argv)
    if args.threads is not None:
        pin_threads(args.threads, restart=argv is None)
    return args.func(args)
