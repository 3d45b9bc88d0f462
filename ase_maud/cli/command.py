"""The ``ase-maud`` command (also ``python -m ase_maud``).

- ``ase-maud relax [NET_FILE]``: relax a net read from a file
  (:mod:`ase_maud.io`: OBJ, COMPAS JSON, ASE trajectory, XYZ plus an edge
  list), or a built-in scene, with Maud; a progress bar on a terminal (else
  ASE's log on stdout), a trajectory for ``ase gui`` and the relaxed net.
- ``ase-maud show FILE``: a picture of a net or a trajectory frame (PNG), or
  the relaxation animated (GIF) (:mod:`ase_maud.form.pictures`).
- ``ase-maud classify FILE``: minimum, saddle of index k or not stationary,
  with the lowest Hessian eigenvalues (:mod:`ase_maud.analysis`).
- ``ase-maud saddles FILE``: the saddles around the net's minimum and the
  minima they join (:mod:`ase_maud.saddles.landscape`): printed, a disconnectivity
  graph and its JSON.
- ``ase-maud bench``: every chosen optimiser from the same starts, force
  calls and wall time against the error; CSV, markdown and PNG in ``--out``.
- ``ase-maud backends``: time per call against accuracy of the registered
  backends (:mod:`ase_maud.backends`).

``--threads N`` pins OpenMP, BLAS and numba to N threads
(:func:`ase_maud.threads.pin_threads`: the loaded pools limited in place by
threadpoolctl); if numba's pool is smaller than N, the command starts itself
again with them set (or, when ``main(argv)`` is called from Python, warns). This module only parses
arguments and calls the library; each command imports what it needs when it
runs (relax needs no matplotlib).

Exit status: 0 done (converged, stationary); 1 not converged within
``--steps`` (relax) or not stationary (classify); 2 an error, said in one line
``ase-maud: error: ...`` on stderr: a bad argument (argparse's own), a file
that cannot be read or written, malformed input, or a run that cannot go on
(:class:`~ase_maud.MaudError`); 130 interrupted (Ctrl-C), in one line. Every
file a command writes is checked before any work (:func:`check_outputs`),
an output that names an input or another output refused
(:mod:`ase_maud.files.output_paths`).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ase_maud.cli.bench import backends_command, bench_command
from ase_maud.cli.classify import classify_command
from ase_maud.cli.options import (
    add_command,
    add_file,
    add_fmax,
    add_loads,
    add_net_options,
    add_threads,
    check_outputs,
    one_line,
    ruled,
    size_option,
)
from ase_maud.cli.relax import relax_command
from ase_maud.cli.saddles import saddles_command
from ase_maud.cli.show import show_command

if TYPE_CHECKING:
    pass

#: The commands and what each does, in one line (``ase-maud --help``).
COMMANDS = {'relax': 'relax a net from a file, or a built-in scene, with Maud',
            'show': 'draw a net or a trajectory frame (PNG), or animate (GIF)',
            'classify': 'minimum, saddle of index k, or not stationary',
            'saddles': 'the saddles around a minimum and the minima they join',
            'bench': 'force calls and wall time against error, per optimiser',
            'backends': 'time per call against accuracy of the calculator backends'}


class _Parser(argparse.ArgumentParser):
    """argparse's parser with its errors in one line, as the command's own
    (``ase-maud relax: error: argument --fmax: ...; see ase-maud relax
    --help``), status 2."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # a number in any notation Python reads is a value, not an option:
        # argparse's own test takes -1 and -.5, not -1e-3 (--load 0 0 -1e-3)
        self._negative_number_matcher = re.compile(
            r'^-(?:\d[\d_]*\.?[\d_]*|\.\d[\d_]*)(?:[eE][-+]?\d+)?$|^-(?:inf|infinity|nan)$',
            re.IGNORECASE)

    def error(self, message: str):
        invalid = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if invalid:   # argparse of Python < 3.14 suggests nothing
            from ase_maud.checks import did_you_mean  # on a usage error only

            message += did_you_mean(invalid[1], re.findall(r"'([^']*)'", invalid[2]))
        self.exit(2, f'{self.prog}: error: {message}; see {self.prog} --help\n')


def _top_parser() -> tuple[argparse.ArgumentParser, Any]:
    """The parser of ``ase-maud`` itself and its (empty) subparsers action."""
    parser = _Parser(
        prog='ase-maud', description='The Maud algorithm for points that '
        'repel and are tied by springs: relax a net from a file or a built-in '
        'scene, draw it, classify its stationary point, or benchmark.',
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='examples:\n  ase-maud relax\n'
        '  ase-maud relax net.obj --fix boundary --out relaxed.obj\n'
        '  ase-maud show maud.traj --gif\n  ase-maud classify maud.traj\n'
        'Each command has its own --help.')
    from importlib.metadata import version  # the installed version, when asked

    parser.add_argument('--version', action='version', version=f"%(prog)s {version('ase-maud')}")
    return parser, parser.add_subparsers(dest='command', metavar='COMMAND')


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of ``ase-maud`` and its commands."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud import backends as registry
    from ase_maud.bench.optimizers import OPTIMIZERS
    from ase_maud.checks import RULES
    from ase_maud.optimize.models.registry import MODELS
    from ase_maud.scenes.catalogue import SCENES, SUITES

    parser, commands = _top_parser()

    p = add_command(
        commands, 'relax', COMMANDS['relax'],
        'Relax the net of NET_FILE (OBJ: points and face/polyline/curve edges; COMPAS '
        'mesh or network JSON; PLY, STL, OFF, VTK, VTU meshes; an ASE trajectory; '
        'or XYZ and any file ASE reads, with an edge list) or, without NET_FILE, a '
        'built-in scene, with Maud. '
        'Shows a progress bar with fmax and the energy on a terminal (else '
        'prints ASE\'s log), writes a trajectory for "ase gui" (it keeps the '
        'springs, a, Q and dim: every command here reads it back), the relaxed '
        'net with --out (like NET_FILE if of its format), and a one-line summary.',
        ['ase-maud relax                       # the default scene, maud.traj',
         'ase-maud relax net.obj --fix boundary --load 0 0 -0.1 --out hung.obj',
         'ase-maud relax lines.obj --fix leaves  # a Rhino line drawing',
         'ase-maud relax net.obj --fix fixed.txt --fmax 1e-6 --traj out.traj '
         '--out relaxed.obj',
         'ase-maud relax points.xyz --edges edges.txt --dim 2 --quiet',
         'ase-maud relax --scene ring --size 100 --log ring.log'])
    p.add_argument('net', nargs='?', metavar='NET_FILE',
                   help='the net to relax (default: the built-in --scene)')
    add_net_options(p)
    add_loads(p)
    p.add_argument('--out', metavar='RELAXED_FILE',
                   help='write the relaxed net here, in the format of its suffix '
                   '(.obj, .json, .traj, .xyz plus NAME.edges.txt, ...)')
    p.add_argument('--forces', metavar='FORCES_CSV',
                   help='write the member forces (i, j, force Q q L, length, force '
                   'density Q q) and the support reactions (rx, ry, rz) as one CSV '
                   'table with a kind column (ase_maud.form.member_forces.write_forces_csv)')
    p.add_argument('--scene', default='weighted_net', choices=SCENES,
                   metavar='NAME', help=f'without NET_FILE, of: {", ".join(SCENES)} '
                   '(default: %(default)s)')
    p.add_argument('--size', type=size_option, help="scene size (default: the "
                   "builder's; molecule takes a name such as C6H6)")
    p.add_argument('--seed', type=ruled('seed', int), default=0,
                   help='seed of the start (default: %(default)s)')
    p.add_argument('--model', default='auto',
                   choices=('auto', *MODELS),
                   help='stiffness model of the step (default: %(default)s)')
    p.add_argument('--method', default='tensor', choices=RULES['method'].choices,
                   help='nodal Maud step (default: %(default)s)')
    p.add_argument('--fmax', type=ruled('fmax'), default=1e-3,
                   help='largest atomic force norm at convergence '
                   '(default: %(default)s)')
    p.add_argument('--steps', type=ruled('steps', int), default=1000,
                   help='step budget (default: %(default)s)')
    p.add_argument('--divergence-factor', type=ruled('divergence_factor'), default=2.0,
                   metavar='F', help='where no finite minimum is proved (nothing '
                   'fixed in some spring component, or constraints other than '
                   'fixed points and axes): the growth of the scene between two '
                   'looks at whether its forces still near a balance; inf: no '
                   'divergence test (default: %(default)s)')
    p.add_argument('--traj', default='maud.traj',
                   help='trajectory file (default: %(default)s)')
    p.add_argument('--progress', action=argparse.BooleanOptionalAction,
                   help='progress bar on stderr instead of ASE\'s log on stdout '
                   '(default: if stderr is a terminal)')
    p.add_argument('--quiet', action='store_true',
                   help='no progress bar and no log: only the summary line')
    p.add_argument('--log', metavar='FILE',
                   help="ASE's per-step log to FILE ('-': stdout, and no bar)")
    add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=relax_command)

    p = add_command(
        commands, 'show', COMMANDS['show'],
        'Draw the net of FILE (any file relax reads; of a trajectory, frame '
        '--frame): springs coloured by their force Q q L (or length) with a '
        'colour bar, supports (fixed points) as black squares (and free points as '
        'dots on nets of at most 400 points), named in a legend; the loads as orange '
        'and the residual forces as red arrows at the scales the legend states, no '
        'residual arrows when the net is converged (max |f| '
        'at most --fmax). In the plane for dim 2, else an orthographic 3D view '
        'from --view. --gif animates every frame of a trajectory (at most 60, '
        'evenly picked) at one colour and arrow scale.',
        ['ase-maud show net.obj                 # net.png',
         'ase-maud show maud.traj --frame 0 -o start.png --view front',
         'ase-maud show maud.traj --color length --view top -o lengths.pdf',
         'ase-maud show maud.traj --gif         # maud.gif'])
    add_file(p)
    p.add_argument('-o', '--output', metavar='PICTURE',
                   help='image file (default: FILE with .png, or .gif with --gif)')
    p.add_argument('--gif', action='store_true', help='animate the frames to a GIF')
    p.add_argument('--fps', type=ruled('count', int), default=8,
                   help='frames per second of the GIF (default: %(default)s)')
    # pictures.COLOURS and VIEWS (named here: importing matplotlib takes a second)
    p.add_argument('--color', '--colour', choices=('force', 'length', 'none'),
                   default='force',
                   help='what colours the springs: their force Q q L, their length, '
                   'or nothing (default: %(default)s)')
    p.add_argument('--labels', action='store_true',
                   help="write each spring's force (or length, with --color length) on "
                   'it; nets of at most 300 springs, not with --gif')
    p.add_argument('--view', choices=('top', 'front', 'side', 'iso'), default='iso',
                   help='side a 3D net is seen from, orthographic: top (down z), front '
                   '(along y), side (along x) or iso (default: %(default)s)')
    add_fmax(p, 'drawn with residual-force arrows')
    add_net_options(p)
    add_loads(p)
    add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=show_command)

    p = add_command(
        commands, 'classify', COMMANDS['classify'],
        'Classify the net of FILE (of a trajectory, frame --frame) by the '
        'eigenvalues of its Hessian on the free degrees of freedom, rigid-body '
        'modes removed (ase_maud.analysis.stationary.classify): minimum, saddle of index k '
        '(k negative eigenvalues), degenerate, or not stationary (fmax above '
        '--fmax, by default the fmax a trajectory was relaxed to; the curvature '
        'there reported). Prints the lowest eigenvalues. '
        'Exit status 0 if stationary, 1 if not.',
        ['ase-maud classify maud.traj',
         'ase-maud classify relaxed.obj --fix boundary --a 0.3 -k 10'])
    add_file(p)
    p.add_argument('-k', type=ruled('count', int), default=6,
                   help='eigenvalues to print (and to compute, above 2000 free '
                   'coordinates) (default: %(default)s)')
    add_fmax(p, 'not stationary')
    add_net_options(p)
    add_loads(p)
    add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=classify_command)

    p = add_command(
        commands, 'saddles', COMMANDS['saddles'],
        'Relax the net of FILE to a minimum (Maud, to --fmax), then climb from it along '
        'each of its --modes lowest Hessian modes, both ways, to index-1 saddles '
        "(Maud(target='saddle')), then make --local local activations (a point's "
        'neighbourhood climbed with the rest held, then the whole net released; '
        "ase_maud.saddles.search), relax each saddle's two sides to the minima it joins, "
        'and keep the distinct minima and saddles (ase_maud.saddles.landscape). Prints what '
        'each attempt did and each saddle with its barriers, draws the '
        'disconnectivity graph (--out) and writes the graph as JSON beside it (--out '
        'with .json). Exit status 0, or 1 if an attempt or descent failed.',
        ['ase-maud saddles cluster.traj --modes 3 --out graph.png',
         'ase-maud saddles net.obj --fix boundary --modes 1 --local 8 --budget 1000',
         'ase-maud saddles dome.traj --modes 0 --mirror   # the snap-through saddle',
         'ase-maud saddles points.xyz --edges edges.txt --dim 2'])
    add_file(p)
    p.add_argument('--modes', type=ruled('modes', int), default=2,
                   help='lowest modes climbed, each both ways (default: %(default)s; 0: '
                   'none, the local activations and the path to --partner or --mirror '
                   'alone)')
    p.add_argument('--local', type=ruled('local', int), default=1,
                   help='local activations after the mode climbs, at points drawn with '
                   '--seed (default: %(default)s)')
    p.add_argument('--budget', type=ruled('budget', int), default=None,
                   help='force-call equivalents (calls, Hessian-vector products, '
                   'Hessians) of each attempt (default: no bound but --steps)')
    p.add_argument('--seed', type=ruled('seed', int), default=0,
                   help='seed of the points activated (default: %(default)s)')
    p.add_argument('--window', type=ruled('window'), default=None, metavar='BARRIER',
                   help='go on in rounds like the first (the next --modes modes, --local '
                   'more points) until --empty-rounds rounds in a row find no new saddle '
                   'whose barrier from the minimum is below BARRIER (energy units; inf: '
                   'any) and that joins it (default: one round)')
    p.add_argument('--empty-rounds', type=ruled('empty_rounds', int), default=6,
                   metavar='ROUNDS', help='with --window, the rounds in a row that find '
                   'no new saddle before the rounds stop (default: %(default)s)')
    p.add_argument('--no-sweep', dest='sweep', action='store_false',
                   help='with --window, stop with the rounds (default: then a local '
                   'activation at every free point not yet activated)')
    p.add_argument('--fmax', type=ruled('fmax'), default=1e-6,
                   help='fmax of every relaxation and climb (default: %(default)s)')
    p.add_argument('--steps', type=ruled('steps', int), default=1000,
                   help='step budget of each (default: %(default)s)')
    p.add_argument('--out', default='graph.png',
                   help='the disconnectivity graph (default: %(default)s); its JSON '
                   'beside it, .json')
    second = p.add_mutually_exclusive_group()
    second.add_argument('--partner', metavar='FILE',
                        help="a second minimum of the net: the points of FILE's last "
                        'frame (read as the net is, the same points in the same order), '
                        'relaxed to --fmax; where the climbs and local activations find '
                        'no saddle, a band of images between the two minima finds the '
                        'one between them (ase_maud.saddles.between_minima.saddle_between)')
    second.add_argument('--mirror', action=argparse.BooleanOptionalAction, default=None,
                        help='the second minimum is the mirror image of the net through '
                        'the plane of its fixed points (a dome and its snap-through; '
                        'ase_maud.saddles.between_minima.reflection), relaxed only if the '
                        'climbs and local activations find no saddle; by default wherever '
                        'the fixed points span a plane the net sags out of '
                        '(--no-mirror: never)')
    spread = p.add_mutually_exclusive_group()
    spread.add_argument('--workers', type=ruled('count', int), metavar='N',
                        help='run the climbs and descents on a dask LocalCluster of N '
                        'worker processes on this machine')
    spread.add_argument('--scheduler', metavar='ADDRESS',
                        help='run them on the dask.distributed scheduler at ADDRESS '
                        '(tcp://host:8786: a cluster of machines)')
    add_net_options(p)
    add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=saddles_command)

    p = add_command(
        commands, 'bench', COMMANDS['bench'],
        'Run every optimiser from the same starts (scene, size, '
        'seed), sampling fmax, energy, force calls, wall and CPU time at '
        'every calculator call; the energy error is against the lowest energy '
        'of a tight reference run. Writes samples.csv (one row per sample), '
        'runs.csv, summary.csv and summary.md (calls and times to each fmax '
        'level, their ratio to the best ASE optimiser and, for CPU time, to '
        'L-BFGS-B), overall.csv (median and worst ratios), and log-log PNGs '
        'of fmax and energy error against calls and time. Ctrl-C stops and '
        'reports what finished.',
        ['ase-maud bench --out maud-bench       # the small suite, every optimiser',
         'ase-maud bench --scenes ring chain --sizes 50 --optimizers Maud FIRE LBFGS'])
    p.add_argument('--scenes', nargs='+', choices=SCENES, metavar='NAME',
                   help=f'of: {", ".join(SCENES)} (default: those of '
                   'the suite, at their suite sizes)')
    p.add_argument('--suite', choices=SUITES, default='small',
                   help='scenes.SUITE (small: under 60 points), scenes.COLLECTIVE '
                   '(collective: collective modes, 40 to 2500 points) or '
                   'scenes.LARGE (large: nets, trees and graphs of 2000 to 10^4 '
                   'points) (default: %(default)s)')
    p.add_argument('--sizes', nargs='+', type=size_option, metavar='SIZE',
                   help='sizes of every scene (default: suite sizes)')
    p.add_argument('--seeds', nargs='+', type=ruled('seed', int), default=[0], metavar='K',
                   help='seeds of the starts (default: 0)')
    p.add_argument('--optimizers', nargs='+', choices=OPTIMIZERS,
                   default=list(OPTIMIZERS), metavar='NAME',
                   help=f'of: {", ".join(OPTIMIZERS)} (default: all)')
    p.add_argument('--fmax', nargs='+', type=ruled('fmax'), default=[1e-3, 1e-6],
                   help='fmax levels of the summary; runs stop at the lowest '
                   '(default: 1e-3 1e-6)')
    p.add_argument('--steps', type=ruled('steps', int), default=10000,
                   help='step budget of every run (default: %(default)s)')
    p.add_argument('--reference', choices=OPTIMIZERS, default='LBFGS',
                   metavar='NAME', help='optimiser of the reference runs '
                   '(default: %(default)s)')
    p.add_argument('--ref-fmax', type=ruled('fmax'), default=1e-9,
                   help='fmax of the reference runs (default: %(default)s)')
    p.add_argument('--energy-rtol', type=ruled('energy_rtol'), default=1e-6,
                   help='relative energy difference from the reference '
                   'beyond which a converged run is in another minimum '
                   '(default: %(default)s)')
    p.add_argument('--out', default='maud-bench',
                   help='output directory (default: %(default)s)')
    p.add_argument('--progress', action=argparse.BooleanOptionalAction,
                   help='progress bar on stderr (default: if it is a tty)')
    add_threads(p, 1, '1')
    p.set_defaults(func=bench_command)

    p = add_command(
        commands, 'backends', COMMANDS['backends'],
        'Time one energy-and-forces call, and one call with the '
        'nodal stiffness, of every backend on N random points, and its '
        'relative error against the numpy reference. Writes backends.csv, '
        'backends.md and backends.png.',
        ['ase-maud backends --natoms 1000 10000 --backends numba fmm'])
    p.add_argument('--natoms', nargs='+', type=ruled('count', int),
                   default=[100, 300, 1000, 3000], metavar='N',
                   help='numbers of points (default: 100 300 1000 3000)')
    needs = '; '.join(f'{b.name} needs {", ".join(b.requires)}'
                      for b in map(registry.get, registry.names())
                      if b.requires)
    p.add_argument('--backends', nargs='+', choices=registry.names(),
                   metavar='NAME',
                   help=f'of: {", ".join(registry.names())} (default: all '
                   f"that are installed but auto, which picks one of them; {needs})")
    p.add_argument('--repeats', type=ruled('count', int), default=3,
                   help='timed calls per point, the best kept '
                   '(default: %(default)s)')
    p.add_argument('--seed', type=ruled('seed', int), default=0,
                   help='seed of the points (default: %(default)s)')
    p.add_argument('--out', default='maud-bench',
                   help='output directory (default: %(default)s)')
    add_threads(p, 1, '1')
    p.set_defaults(func=backends_command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ase-maud`` on ``argv`` (default ``sys.argv[1:]``); return the
    exit status (module docstring). Without a command, print the help on
    stderr and return 2 (a usage error); ``--version`` prints the version.
    Bad input, files that cannot be read or written and runs that cannot go
    on (ValueError, OSError, :class:`~ase_maud.MaudError`) are said in one
    line on stderr, status 2. Without a command nothing but argparse is
    imported (``ase-maud --help`` answers at once)."""
    words = sys.argv[1:] if argv is None else list(argv)
    if not COMMANDS.keys() & set(words):
        parser, commands = _top_parser()
        for name, text in COMMANDS.items():
            commands.add_parser(name, help=text)
        parser.parse_args(words)   # --help, --version, or an error
        parser.print_help(sys.stderr)   # no command: a usage error, as argparse's own
        return 2
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.errors import MaudError
    from ase_maud.kernel_cache import compile_notice
    from ase_maud.threads import pin_threads

    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == 'relax' and args.net is None and (
            args.edges or args.fixed or args.dim):
        parser.error('relax: --edges, --fix and --dim need NET_FILE')
    if args.command == 'show' and args.gif and args.labels:
        parser.error('show: --labels writes on one picture, not on a --gif')
    args.argv = words
    try:
        check_outputs(args)
        if args.threads is not None:
            pin_threads(args.threads, restart=argv is None)
        with compile_notice():   # whenever a kernel compiles, whatever the command
            return args.func(args)
    except (ValueError, OSError, MaudError) as error:
        print(f'{parser.prog}: error: {one_line(error)}', file=sys.stderr)
        return 2
    except KeyboardInterrupt as error:   # every output is whole: replaced when complete
        print(f'{parser.prog}: {one_line(error) if str(error) else "interrupted"}',
              file=sys.stderr)
        return 130
