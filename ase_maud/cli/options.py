"""Options and checks shared by the commands: net options, fmax, files,
threads, and the one-line error.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass


def size_option(text):
    """A scene size: an int if it reads as one, else the text ('C6H6')."""
    try:
        return int(text)
    except ValueError:
        return text


def ruled(name: str, parse=float):
    """An argparse type: the text parsed by ``parse``, then checked by
    ``ase_maud.checks.RULES[name]`` (its message on a bad value)."""
    def convert(text):
        # Imported when the command runs, so that ase-maud --help answers at once.
        # Imported when the command runs, so that ase-maud --help answers at once.
        from ase_maud.checks import check

        try:
            return check(name, parse(text))
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
    convert.__name__ = name   # argparse names the type in its own messages
    return convert


def net_options(args: argparse.Namespace) -> dict:
    """The keywords of :func:`ase_maud.io.nets.read_net` from --edges, --fix,
    --a, --Q and --dim, and --load where the command takes it."""
    return {'edges': args.edges, 'fixed': args.fixed, 'a': args.a, 'Q': args.Q,
            'dim': args.dim, 'load': getattr(args, 'load', None)}


def set_net_tables(atoms, args: argparse.Namespace) -> None:
    """The --loads and --q tables (or number) of a command that takes them
    (:func:`add_loads`), set on the net ``atoms``."""
    from ase_maud.io.nets import set_tables  # when a command runs: ase-maud --help stays fast

    set_tables(atoms, loads=getattr(args, 'loads', None), q=getattr(args, 'q', None))


def add_loads(parser, file='NET_FILE'):
    """--load or --loads, and --q: the loads and force densities of a net
    (relax, show and classify take them alike)."""
    loads = parser.add_mutually_exclusive_group()
    loads.add_argument('--load', nargs=3, type=ruled('loads'), metavar=('X', 'Y', 'Z'),
                       help='a constant load (force units) on every free point, e.g. '
                       "self-weight --load 0 0 -0.1; replaces the file's loads "
                       f"(default: those of {file}: COMPAS px, py, pz, or a trajectory's; "
                       "a built-in scene's)")
    loads.add_argument('--loads', metavar='LOADS_CSV',
                       help='per-point loads from a CSV table with the header i,px,py,pz '
                       '(0-based point index, force units; points not listed: none), '
                       "replacing the file's")
    parser.add_argument('--q', metavar='Q_CSV',
                        help='per-edge force densities from a CSV table with the header '
                        'i,j,q (the two points of a spring, its multiplier of Q; edges not '
                        'listed keep theirs), or one number for every edge; negative: '
                        'compression (an arch or gridshell, e.g. --q -1 with --load 0 0 '
                        '-0.1; with --a > 0 the equilibrium found is a stationary point, '
                        'not a minimum)')


def judging_fmax(args: argparse.Namespace) -> tuple[float | None, str]:
    """The fmax at which show and classify call a net converged, and why:
    --fmax, else the fmax a trajectory was relaxed to
    (:func:`ase_maud.io.nets.relaxed_fmax`), else None (analysis's 1e-6 Q a)."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.io.nets import relaxed_fmax

    if args.fmax is not None:
        return args.fmax, '--fmax'
    relaxed = relaxed_fmax(args.file)
    return relaxed, '1e-6 Q a' if relaxed is None else 'the fmax it was relaxed to'


def add_fmax(parser, what: str) -> None:
    parser.add_argument('--fmax', '--ftol', type=ruled('fmax'),
                        help=f'fmax above which the net is {what} (default: the fmax a '
                        'trajectory of relax was relaxed to, stored in it; else 1e-6 Q a)')


def picture_path(args: argparse.Namespace) -> str:
    """The image ``ase-maud show`` writes: -o, or FILE with .png (.gif)."""
    return args.output or str(Path(args.file).with_suffix('.gif' if args.gif else '.png'))


def log_file(log: str | None):
    """--log as ASE's optimisers take it: the name, or for a named pipe or a
    device an open file (opened without waiting for a reader: a pipe that
    nothing reads is an OSError at once, where ASE's open would wait)."""

    from ase_maud.files.atomic_replace import is_special, open_in_place  # when a command runs

    if log in (None, '-') or not is_special(log):
        return log
    return os.fdopen(open_in_place(log), 'a', encoding='utf-8')


def check_outputs(args: argparse.Namespace) -> None:
    """Every file the command of ``args`` will write, checked before any
    work: a ValueError naming the option and what is wrong, or an output
    that names an input or another output (:mod:`ase_maud.files.output_paths`)."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.checks import check_writable
    from ase_maud.files.output_paths import check_distinct, check_own_json
    from ase_maud.io.nets import check_net_path, edges_path, net_format

    if args.command == 'relax':
        check_writable('--traj', args.traj)
        if args.log not in (None, '-'):
            check_writable('--log', args.log)
        if args.out:
            check_net_path('--out', args.out)
            if net_format(args.out) == 'ase':   # the edge list written beside it
                check_writable("--out's edge list", edges_path(args.out))
        if args.forces:
            check_writable('--forces', args.forces)
    elif args.command == 'show':
        from matplotlib.figure import Figure

        path = check_writable('--output', picture_path(args))
        known = ['gif'] if args.gif else sorted(Figure().canvas.get_supported_filetypes())
        if path.suffix.lower().lstrip('.') not in known:
            raise ValueError(f'--output {str(path)!r}: ' + (
                'an animation (--gif) is written as .gif' if args.gif else
                f'a picture is written as one of .{", .".join(known)}'))
    elif args.command == 'saddles':
        if args.partner is not None and not Path(args.partner).is_file():
            raise ValueError(f'--partner {args.partner!r}: no such file')
        check_writable('--out', args.out)
        check_writable('--out', graph_json(args))
        from ase_maud.saddles.landscape import GRAPH_KEYS
        check_own_json(f'--out {args.out!r} (its graph JSON)', graph_json(args),
                       GRAPH_KEYS, 'ase-maud saddles')
    elif args.command in ('bench', 'backends'):
        check_writable('--out', args.out, directory=True)
    check_distinct(*named_files(args))


def named_files(args: argparse.Namespace) -> tuple[list, list]:
    """The (argument, file) pairs the command of ``args`` reads and writes
    (:func:`ase_maud.files.output_paths.check_distinct`): the net, its edge list (given,
    or the one beside a point file), its --fix file and relax's --loads and
    --q tables; --traj, --log, --out and the edge list or graph JSON written
    beside it, relax's --forces, --output."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.io.nets import FIX_RULES, edges_path, net_format

    net = getattr(args, 'net', None) or getattr(args, 'file', None)
    inputs = [] if net is None else [
        ('FILE' if args.command != 'relax' else 'NET_FILE', net),
        ('--edges', args.edges or (edges_path(net) if net_format(net) == 'ase' else None)),
        ('--fix', None if args.fixed in (None, *FIX_RULES) else args.fixed)]
    outputs = []
    if args.command in ('relax', 'show', 'classify'):
        inputs += [('--loads', args.loads), ('--q', args.q)]
    if args.command == 'relax':
        outputs = [('--traj', args.traj), ('--log', None if args.log == '-' else args.log),
                   ('--out', args.out), ('--forces', args.forces)]
        if args.out and net_format(args.out) == 'ase':
            outputs.append(("--out's edge list", edges_path(args.out)))
    elif args.command == 'show':
        outputs = [('--output', picture_path(args))]
    elif args.command == 'saddles':
        inputs.append(('--partner', args.partner))
        outputs = [('--out', args.out), ("--out's graph JSON", graph_json(args))]
    return inputs, outputs


def one_line(error: BaseException) -> str:
    """The message of ``error`` on one line (an OSError's as 'file: reason')."""
    if isinstance(error, OSError) and error.filename and error.strerror:
        text = f'{error.filename}: {error.strerror}'
    else:
        text = str(error) or type(error).__name__
    return ' '.join(text.split())


def add_file(parser):
    """FILE and --frame: the net (or trajectory frame) a command reads."""
    parser.add_argument('file', metavar='FILE', help='net or trajectory')
    parser.add_argument('--frame', type=int, default=-1,
                        help='frame of a trajectory (default: the last)')


def add_net_options(parser):
    """--edges, --fix, --a, --Q and --dim of a command that reads a net."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.physics.topology import A_PER_MEAN_SPRING

    parser.add_argument('--edges', metavar='EDGES_FILE',
                        help='edge list: two 0-based point indices per line (default: '
                        "the file's own springs, or NAME.edges.txt beside NAME.xyz)")
    parser.add_argument('--fix', '--fixed', dest='fixed', metavar='RULE_OR_FILE',
                        help="the points held fixed: 'boundary' (a mesh's: on edges of one "
                        "face), 'outer' (its outer rim only, not a hole's), "
                        "'leaves' (a network's: on one spring), or a file of 0-based "
                        "indices, one or more per line (default: the file's own: "
                        'trajectory constraints, COMPAS is_anchor or is_fixed)')
    parser.add_argument('--a', type=ruled('a'),
                        help='length a of the repulsion a^3 Q / L; 0: none, the '
                        'force-density equilibrium of springs and loads (default: stored '
                        'in a trajectory, else 0 if the supports hold every spring '
                        f'component, else {A_PER_MEAN_SPRING:g} x the mean spring length)')
    parser.add_argument('--Q', type=ruled('Q'),
                        help='spring constant Q (default: stored in a trajectory, else 1)')
    parser.add_argument('--dim', type=int, choices=(2, 3),
                        help='2: points on a plane z = const; 3 (default: stored in a '
                        'trajectory, else 2 if every z is equal, else 3)')


def add_command(commands, name, help, description, examples):
    """A subcommand parser with ``examples`` (lines) as its --help epilog."""
    return commands.add_parser(
        name, help=help, description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='examples:\n' + '\n'.join(f'  {line}' for line in examples))


def add_threads(parser, default, default_text):
    parser.add_argument('--threads', type=ruled('count', int), default=default, metavar='N',
                        help='pin OpenMP, BLAS and numba to N threads '
                        f'(default: {default_text})')


def graph_json(args: argparse.Namespace) -> str:
    """The JSON of ``ase-maud saddles``: --out with .json."""
    return str(Path(args.out).with_suffix('.json'))
