"""The ``ase-maud`` command (also ``python -m ase_maud``).

- ``ase-maud relax [NET_FILE]``: relax a net read from a file
  (:mod:`ase_maud.io`: OBJ, COMPAS JSON, ASE trajectory, XYZ plus an edge
  list), or a built-in scene, with Maud; a progress bar on a terminal (else
  ASE's log on stdout), a trajectory for ``ase gui`` and the relaxed net.
- ``ase-maud show FILE``: a picture of a net or a trajectory frame (PNG), or
  the relaxation animated (GIF) (:mod:`ase_maud.pictures`).
- ``ase-maud classify FILE``: minimum, saddle of index k or not stationary,
  with the lowest Hessian eigenvalues (:mod:`ase_maud.analysis`).
- ``ase-maud saddles FILE``: the saddles around the net's minimum and the
  minima they join (:mod:`ase_maud.landscape`): printed, a disconnectivity
  graph and its JSON.
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

Exit status: 0 done (converged, stationary); 1 not converged within
``--steps`` (relax) or not stationary (classify); 2 an error, said in one line
``ase-maud: error: ...`` on stderr: a bad argument (argparse's own), a file
that cannot be read or written, malformed input, or a run that cannot go on
(:class:`~ase_maud.MaudError`); 130 interrupted (Ctrl-C), in one line. Every
file a command writes is checked before any work (:func:`check_outputs`),
an output that names an input or another output refused
(:mod:`ase_maud.paths`).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ase import Atoms

#: The commands and what each does, in one line (``ase-maud --help``).
COMMANDS = {'relax': 'relax a net from a file, or a built-in scene, with Maud',
            'show': 'draw a net or a trajectory frame (PNG), or animate (GIF)',
            'classify': 'minimum, saddle of index k, or not stationary',
            'saddles': 'the saddles around a minimum and the minima they join',
            'bench': 'force calls and wall time against error, per optimiser',
            'backends': 'time per call against accuracy of the calculator backends'}


def _size(text):
    """A scene size: an int if it reads as one, else the text ('C6H6')."""
    try:
        return int(text)
    except ValueError:
        return text


def _ruled(name: str, parse=float):
    """An argparse type: the text parsed by ``parse``, then checked by
    ``ase_maud.checks.RULES[name]`` (its message on a bad value)."""
    def convert(text):
        from .checks import check

        try:
            return check(name, parse(text))
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
    convert.__name__ = name   # argparse names the type in its own messages
    return convert


def _net_options(args: argparse.Namespace) -> dict:
    """The keywords of :func:`ase_maud.io.read_net` from --edges, --fix,
    --a, --Q and --dim."""
    return {'edges': args.edges, 'fixed': args.fixed, 'a': args.a, 'Q': args.Q,
            'dim': args.dim}


def _progress_bar(opt, atoms, fmax: float, steps: int):
    """A tqdm bar on stderr of the optimizer ``opt``'s steps out of
    ``steps``, showing fmax against its target ``fmax`` and the energy."""
    from tqdm import tqdm

    bar = tqdm(total=steps, unit='step', file=sys.stderr, dynamic_ncols=True)

    def advance():
        now = (atoms.get_forces()**2).sum(axis=1).max() ** 0.5
        bar.set_postfix_str(f'fmax {now:.3g} (target {fmax:.3g}), energy '
                            f'{atoms.get_potential_energy():.10g}', refresh=False)
        bar.update(opt.nsteps - bar.n)   # observers run at step 0 too

    opt.attach(advance)
    return bar


def relax(args: argparse.Namespace) -> int:
    """``ase-maud relax``: exit status 0 if converged, else 1."""
    from . import kernels_cached
    from .bench.runner import CallRecorder
    from .forcedensity import solve_force_density
    from .io import mean_spring_length, net_format, read_net, set_tables, write_net
    from .optimizer import Maud
    from .paths import StagedTrajectory
    from .results import describe_result, form_result, form_warnings, write_forces_csv
    from .scenes import build
    from .topology import free_point_loads

    if args.net is None:
        atoms = build(args.scene, args.size, seed=args.seed,
                      **{k: v for k, v in (('a', args.a), ('Q', args.Q)) if v is not None})
        if args.load is not None:
            atoms.calc.set(loads=free_point_loads(atoms, args.load))
        label = args.scene
    else:
        atoms = read_net(args.net, load=args.load, **_net_options(args))
        label = Path(args.net).name
    set_tables(atoms, loads=args.loads, q=args.q)
    a, springs = atoms.calc.parameters['a'], atoms.calc.parameters.get('springs', ())
    share = (f' ({a / mean_spring_length(atoms.positions, springs):.3g} x the mean spring '
             'length at the start)' if a else ' (the force-density equilibrium: no '
             'repulsion)') if len(springs) else ''
    if a == 0:
        solve_force_density(atoms)   # Maud then has nothing left to do
    elif not kernels_cached():
        print('compiling the kernels (first run only, ~20 s)...', file=sys.stderr,
              flush=True)
    start = atoms.positions.copy()
    progress = (sys.stderr.isatty() if args.progress is None else args.progress) \
        and not args.quiet and args.log != '-'
    logfile = args.log or (None if progress or args.quiet else '-')
    with CallRecorder(atoms.calc) as recorder, StagedTrajectory(args.traj) as staged, \
            Maud(atoms, model=args.model, method=args.method, logfile=logfile,
                 trajectory=staged.trajectory,
                 divergence_factor=args.divergence_factor) as opt:
        opt.attach(staged.keep)   # the trajectory replaces --traj at its first frame
        bar = _progress_bar(opt, atoms, args.fmax, args.steps) if progress else None
        try:
            converged = opt.run(fmax=args.fmax, steps=args.steps)
        except KeyboardInterrupt:
            raise KeyboardInterrupt(
                f'interrupted at step {opt.nsteps}; ' + (
                    f'trajectory {args.traj} holds the steps so far' if staged.kept
                    else f'{args.traj} left as it was')
                + (', --out not written' if args.out else '')) from None
        finally:
            if bar is not None:
                bar.close()
    fmax = (atoms.get_forces()**2).sum(axis=1).max() ** 0.5
    result = form_result(atoms)
    written = f'trajectory {args.traj}'
    if args.out:
        like = args.net if args.net and net_format(args.net) == net_format(args.out) else None
        written += ', relaxed net ' + ' '.join(map(str, write_net(args.out, atoms, like=like,
                                                                  result=result)))
    if args.forces:
        written += f', forces {write_forces_csv(args.forces, result)}'
    print(f'{"converged" if converged else "NOT converged"}: {label} '
          f'{len(atoms)} points, {opt.nsteps} steps, '
          f'{len(recorder.samples)} force calls, energy '
          f'{atoms.get_potential_energy():.12g}, fmax {fmax:.3g}, a {a:.4g}{share}; '
          f'{describe_result(result)}; {written}')
    for warning in form_warnings(atoms, start, result) if args.net is not None else ():
        print(f'ase-maud: warning: {warning}', file=sys.stderr)
    return 0 if converged else 1


def show(args: argparse.Namespace) -> int:
    """``ase-maud show``: exit status 0."""
    from .atomic import replace_with
    from .io import read_frames, read_net
    from .pictures import save_animation, save_picture

    out = _picture_path(args)
    style = {'colour': args.color, 'view': args.view, 'ftol': _judging_fmax(args)[0]}
    if args.gif:
        frames = read_frames(args.file, **_net_options(args))
        count = []
        replace_with(out, lambda temporary: count.append(
            save_animation(frames, temporary, fps=args.fps, **style)))
        print(f'wrote {out} ({count[0]} of {len(frames)} frames)')
    else:
        atoms = read_net(args.file, index=args.frame, **_net_options(args))
        replace_with(out, lambda temporary: save_picture(atoms, temporary, **style,
                                                         labels=args.labels))
        print(f'wrote {out}')
    return 0


def _judging_fmax(args: argparse.Namespace) -> tuple[float | None, str]:
    """The fmax at which show and classify call a net converged, and why:
    --fmax, else the fmax a trajectory was relaxed to
    (:func:`ase_maud.io.relaxed_fmax`), else None (analysis's 1e-6 Q a)."""
    from .io import relaxed_fmax

    if args.fmax is not None:
        return args.fmax, '--fmax'
    relaxed = relaxed_fmax(args.file)
    return relaxed, '1e-6 Q a' if relaxed is None else 'the fmax it was relaxed to'


def _add_fmax(parser, what: str) -> None:
    parser.add_argument('--fmax', '--ftol', type=_ruled('fmax'),
                        help=f'fmax above which the net is {what} (default: the fmax a '
                        'trajectory of relax was relaxed to, stored in it; else 1e-6 Q a)')


def describe(point) -> str:
    """The verdict of a :class:`~ase_maud.analysis.StationaryPoint` in words:
    'minimum', 'saddle of index k', 'maximum' or 'degenerate (...)', after
    'not stationary; the curvature there: ' if it is not stationary."""
    verdict = {'saddle': f'saddle of index {point.index}',
               'degenerate': f'degenerate ({point.n_zero} zero modes, '
                             f'{point.n_negative} negative)'}.get(point.verdict, point.verdict)
    if not point.stationary:
        verdict = f'not stationary (fmax {point.fmax:.3g}); the curvature there: {verdict}'
    return verdict


def classify(args: argparse.Namespace) -> int:
    """``ase-maud classify``: exit status 0 if stationary, else 1. Stationary
    means fmax at most ``--fmax``, by default the fmax a trajectory was
    relaxed to, else analysis's default (:func:`_judging_fmax`)."""
    from .analysis import classify as classify_point
    from .io import read_net

    atoms = read_net(args.file, index=args.frame, **_net_options(args))
    ftol, why = _judging_fmax(args)
    with warnings.catch_warnings():   # "not stationary" is said below
        warnings.simplefilter('ignore', UserWarning)
        point = classify_point(atoms, k=args.k, ftol=ftol)
    print(f'{describe(point)}: {Path(args.file).name} {len(atoms)} points, '
          f'{point.n_modes} free non-rigid modes ({point.n_fixed} fixed coordinates, '
          f'{point.n_rigid} rigid-body modes removed), fmax {point.fmax:.3g} '
          f'(stationary up to {point.ftol:.3g}, {why})')
    lowest = ' '.join(f'{value:.6g}' for value in point.eigenvalues[:args.k])
    print(f'lowest eigenvalues ({point.method}, units of Q): {lowest}')
    return 0 if point.stationary else 1


def saddles(args: argparse.Namespace) -> int:
    """``ase-maud saddles``: the net relaxed to a minimum, its landscape
    (:func:`ase_maud.landscape.landscape`) printed, drawn (--out) and written
    as JSON beside the picture; exit status 0 (1 if a climb or descent
    failed)."""
    import json

    from .atomic import replace_text, replace_with
    from .io import read_net
    from .landscape import landscape
    from .optimizer import Maud
    from .pictures import save_disconnectivity

    atoms = read_net(args.file, index=args.frame, **_net_options(args))
    Maud(atoms, logfile=None).run(fmax=args.fmax, steps=args.steps)
    partner = _partner(args, atoms)
    with _dask_client(args.workers, args.scheduler) as client:
        found = landscape(atoms, modes=args.modes, fmax=args.fmax, steps=args.steps,
                          client=client, local=args.local, budget=args.budget,
                          seed=args.seed, partner=partner, mirror=args.mirror,
                          window=args.window, empty_rounds=args.empty_rounds)
    print(found.search.report())
    energies = [m.get_potential_energy() for m in found.minima]
    barriers = [s.get_potential_energy() for s in found.saddles]
    for s, ((i, j), (up_i, up_j)) in enumerate(zip(found.joins, found.barriers(),
                                                     strict=True)):
        print(f'saddle {s}: energy {barriers[s]:.10g}, joins minimum {i} '
              f'(barrier {up_i:.6g}) and minimum {j} (barrier {up_j:.6g})')
    print(f'{len(energies)} minima (lowest {min(energies):.10g}), {len(barriers)} saddles, '
          f'{found.failed} failed attempts or descents; {args.out} and '
          f'{_graph_json(args)}')
    replace_with(args.out, lambda temporary: save_disconnectivity(
        energies, barriers, found.joins, temporary))
    replace_text(_graph_json(args), json.dumps(found.todict()))
    return 1 if found.failed else 0


def _partner(args: argparse.Namespace, minimum: Atoms) -> Atoms | None:
    """The second minimum of ``ase-maud saddles`` given as --partner (None
    without): the points of that file (its last frame, read as the net is)
    on the net of ``minimum``, relaxed by Maud to --fmax (--mirror asks the
    search for the mirror image instead). A ValueError names a --partner
    file whose points are not the net's, or one that does not relax."""
    from .bench.runner import fresh_copy
    from .io import read_net
    from .optimizer import Maud

    if args.partner is None:
        return None
    read = read_net(args.partner, **_net_options(args))
    if len(read) != len(minimum):
        raise ValueError(f'--partner {args.partner!r} has {len(read)} points, the net '
                         f'{args.file!r} has {len(minimum)}: a second minimum of the net '
                         'has its points, in its order')
    partner = fresh_copy(minimum)
    partner.positions = read.positions
    if not Maud(partner, logfile=None).run(fmax=args.fmax, steps=args.steps):
        raise ValueError(f'--partner {args.partner!r}: its points did not relax to fmax '
                         f'{args.fmax:g} in {args.steps} steps')
    return partner


@contextlib.contextmanager
def _dask_client(workers: int | None, scheduler: str | None):
    """A dask.distributed Client: of a LocalCluster of ``workers`` processes
    (one thread each), or of the scheduler at ``scheduler``; None for
    neither. A ValueError if dask.distributed is not installed."""
    if workers is None and scheduler is None:
        yield None
        return
    try:
        import distributed
    except ImportError:
        raise ValueError("--workers and --scheduler need dask.distributed: pip install "
                         "'ase_maud[cluster]'") from None
    if scheduler is not None:
        with distributed.Client(scheduler) as client:
            yield client
        return
    with distributed.LocalCluster(n_workers=workers, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        yield client


def _graph_json(args: argparse.Namespace) -> str:
    """The JSON of ``ase-maud saddles``: --out with .json."""
    return str(Path(args.out).with_suffix('.json'))


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


def _picture_path(args: argparse.Namespace) -> str:
    """The image ``ase-maud show`` writes: -o, or FILE with .png (.gif)."""
    return args.output or str(Path(args.file).with_suffix('.gif' if args.gif else '.png'))


def check_outputs(args: argparse.Namespace) -> None:
    """Every file the command of ``args`` will write, checked before any
    work: a ValueError naming the option and what is wrong, or an output
    that names an input or another output (:mod:`ase_maud.paths`)."""
    from .checks import check_writable
    from .io import check_net_path
    from .paths import check_distinct, check_own_json

    if args.command == 'relax':
        check_writable('--traj', args.traj)
        if args.log not in (None, '-'):
            check_writable('--log', args.log)
        if args.out:
            check_net_path('--out', args.out)
        if args.forces:
            check_writable('--forces', args.forces)
    elif args.command == 'show':
        from matplotlib.figure import Figure

        path = check_writable('--output', _picture_path(args))
        known = ['gif'] if args.gif else sorted(Figure().canvas.get_supported_filetypes())
        if path.suffix.lower().lstrip('.') not in known:
            raise ValueError(f'--output {str(path)!r}: ' + (
                'an animation (--gif) is written as .gif' if args.gif else
                f'a picture is written as one of .{", .".join(known)}'))
    elif args.command == 'saddles':
        if args.partner is not None and not Path(args.partner).is_file():
            raise ValueError(f'--partner {args.partner!r}: no such file')
        check_writable('--out', args.out)
        check_writable('--out', _graph_json(args))
        from .landscape import GRAPH_KEYS
        check_own_json(f'--out {args.out!r} (its graph JSON)', _graph_json(args),
                       GRAPH_KEYS, 'ase-maud saddles')
    elif args.command in ('bench', 'backends'):
        check_writable('--out', args.out, directory=True)
    check_distinct(*_files(args))


def _files(args: argparse.Namespace) -> tuple[list, list]:
    """The (argument, file) pairs the command of ``args`` reads and writes
    (:func:`ase_maud.paths.check_distinct`): the net, its edge list (given,
    or the one beside a point file), its --fix file and relax's --loads and
    --q tables; --traj, --log, --out and the edge list or graph JSON written
    beside it, relax's --forces, --output."""
    from .io import FIX_RULES, edges_path, net_format

    net = getattr(args, 'net', None) or getattr(args, 'file', None)
    inputs = [] if net is None else [
        ('FILE' if args.command != 'relax' else 'NET_FILE', net),
        ('--edges', args.edges or (edges_path(net) if net_format(net) == 'ase' else None)),
        ('--fix', None if args.fixed in (None, *FIX_RULES) else args.fixed)]
    outputs = []
    if args.command == 'relax':
        inputs += [('--loads', args.loads), ('--q', args.q)]
        outputs = [('--traj', args.traj), ('--log', None if args.log == '-' else args.log),
                   ('--out', args.out), ('--forces', args.forces)]
        if args.out and net_format(args.out) == 'ase':
            outputs.append(("--out's edge list", edges_path(args.out)))
    elif args.command == 'show':
        outputs = [('--output', _picture_path(args))]
    elif args.command == 'saddles':
        inputs.append(('--partner', args.partner))
        outputs = [('--out', args.out), ("--out's graph JSON", _graph_json(args))]
    return inputs, outputs


def _one_line(error: BaseException) -> str:
    """The message of ``error`` on one line (an OSError's as 'file: reason')."""
    if isinstance(error, OSError) and error.filename and error.strerror:
        text = f'{error.filename}: {error.strerror}'
    else:
        text = str(error) or type(error).__name__
    return ' '.join(text.split())


def _add_file(parser):
    """FILE and --frame: the net (or trajectory frame) a command reads."""
    parser.add_argument('file', metavar='FILE', help='net or trajectory')
    parser.add_argument('--frame', type=int, default=-1,
                        help='frame of a trajectory (default: the last)')


def _add_net_options(parser):
    """--edges, --fix, --a, --Q and --dim of a command that reads a net."""
    from .io import A_PER_MEAN_SPRING

    parser.add_argument('--edges', metavar='EDGES_FILE',
                        help='edge list: two 0-based point indices per line (default: '
                        "the file's own springs, or NAME.edges.txt beside NAME.xyz)")
    parser.add_argument('--fix', '--fixed', dest='fixed', metavar='RULE_OR_FILE',
                        help="the points held fixed: 'boundary' (a mesh's: on edges of one "
                        "face), 'outer' (its outer rim only, not a hole's), "
                        "'leaves' (a network's: on one spring), or a file of 0-based "
                        "indices, one or more per line (default: the file's own: "
                        'trajectory constraints, COMPAS is_anchor or is_fixed)')
    parser.add_argument('--a', type=_ruled('a'),
                        help='length a of the repulsion a^3 Q / L; 0: none, the '
                        'force-density equilibrium of springs and loads (default: stored '
                        'in a trajectory, else 0 if the supports hold every spring '
                        f'component, else {A_PER_MEAN_SPRING:g} x the mean spring length)')
    parser.add_argument('--Q', type=_ruled('Q'),
                        help='spring constant Q (default: stored in a trajectory, else 1)')
    parser.add_argument('--dim', type=int, choices=(2, 3),
                        help='2: points on a plane z = const; 3 (default: stored in a '
                        'trajectory, else 2 if every z is equal, else 3)')


def _command(commands, name, help, description, examples):
    """A subcommand parser with ``examples`` (lines) as its --help epilog."""
    return commands.add_parser(
        name, help=help, description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='examples:\n' + '\n'.join(f'  {line}' for line in examples))


def _add_threads(parser, default, default_text):
    parser.add_argument('--threads', type=_ruled('count', int), default=default, metavar='N',
                        help='pin OpenMP, BLAS and numba to N threads '
                        f'(default: {default_text})')


class _Parser(argparse.ArgumentParser):
    """argparse's parser with its errors in one line, as the command's own
    (``ase-maud relax: error: argument --fmax: ...; see ase-maud relax
    --help``), status 2."""

    def error(self, message: str):
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
    return parser, parser.add_subparsers(dest='command', metavar='COMMAND')


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of ``ase-maud`` and its commands."""
    from . import backends as registry
    from .bench.optimizers import OPTIMIZERS
    from .checks import RULES
    from .models import MODELS
    from .scenes import SCENES, SUITES

    parser, commands = _top_parser()

    p = _command(
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
    _add_net_options(p)
    loads = p.add_mutually_exclusive_group()
    loads.add_argument('--load', nargs=3, type=_ruled('loads'), metavar=('X', 'Y', 'Z'),
                       help='a constant load (force units) on every free point, e.g. '
                       "self-weight --load 0 0 -0.1; replaces the file's or scene's loads "
                       '(default: those of NET_FILE: COMPAS px, py, pz, or a trajectory\'s; '
                       'the scene\'s)')
    loads.add_argument('--loads', metavar='LOADS_CSV',
                       help='per-point loads from a CSV table with the header i,px,py,pz '
                       '(0-based point index, force units; points not listed: none), '
                       "replacing the file's or scene's")
    p.add_argument('--q', metavar='Q_CSV',
                   help='per-edge force densities from a CSV table with the header i,j,q '
                   '(the two points of a spring, its multiplier of Q; edges not listed '
                   'keep theirs)')
    p.add_argument('--out', metavar='RELAXED_FILE',
                   help='write the relaxed net here, in the format of its suffix '
                   '(.obj, .json, .traj, .xyz plus NAME.edges.txt, ...)')
    p.add_argument('--forces', metavar='FORCES_CSV',
                   help='write the member forces (i, j, force Q q L, length, force '
                   'density Q q) and the support reactions (rx, ry, rz) as one CSV '
                   'table with a kind column (ase_maud.results.write_forces_csv)')
    p.add_argument('--scene', default='weighted_net', choices=SCENES,
                   metavar='NAME', help=f'without NET_FILE, of: {", ".join(SCENES)} '
                   '(default: %(default)s)')
    p.add_argument('--size', type=_size, help="scene size (default: the "
                   "builder's; molecule takes a name such as C6H6)")
    p.add_argument('--seed', type=_ruled('seed', int), default=0,
                   help='seed of the start (default: %(default)s)')
    p.add_argument('--model', default='auto',
                   choices=('auto', *MODELS),
                   help='stiffness model of the step (default: %(default)s)')
    p.add_argument('--method', default='tensor', choices=RULES['method'].choices,
                   help='nodal Maud step (default: %(default)s)')
    p.add_argument('--fmax', type=_ruled('fmax'), default=1e-3,
                   help='largest atomic force norm at convergence '
                   '(default: %(default)s)')
    p.add_argument('--steps', type=_ruled('steps', int), default=1000,
                   help='step budget (default: %(default)s)')
    p.add_argument('--divergence-factor', type=_ruled('divergence_factor'), default=2.0,
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
    _add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=relax)

    p = _command(
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
    _add_file(p)
    p.add_argument('-o', '--output', metavar='PICTURE',
                   help='image file (default: FILE with .png, or .gif with --gif)')
    p.add_argument('--gif', action='store_true', help='animate the frames to a GIF')
    p.add_argument('--fps', type=_ruled('count', int), default=8,
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
    _add_fmax(p, 'drawn with residual-force arrows')
    _add_net_options(p)
    _add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=show)

    p = _command(
        commands, 'classify', COMMANDS['classify'],
        'Classify the net of FILE (of a trajectory, frame --frame) by the '
        'eigenvalues of its Hessian on the free degrees of freedom, rigid-body '
        'modes removed (ase_maud.analysis.classify): minimum, saddle of index k '
        '(k negative eigenvalues), degenerate, or not stationary (fmax above '
        '--fmax, by default the fmax a trajectory was relaxed to; the curvature '
        'there reported). Prints the lowest eigenvalues. '
        'Exit status 0 if stationary, 1 if not.',
        ['ase-maud classify maud.traj',
         'ase-maud classify relaxed.obj --fix boundary --a 0.3 -k 10'])
    _add_file(p)
    p.add_argument('-k', type=_ruled('count', int), default=6,
                   help='eigenvalues to print (and to compute, above 2000 free '
                   'coordinates) (default: %(default)s)')
    _add_fmax(p, 'not stationary')
    _add_net_options(p)
    _add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=classify)

    p = _command(
        commands, 'saddles', COMMANDS['saddles'],
        'Relax the net of FILE to a minimum (Maud, to --fmax), then climb from it along '
        'each of its --modes lowest Hessian modes, both ways, to index-1 saddles '
        "(Maud(target='saddle')), then make --local local activations (a point's "
        'neighbourhood climbed with the rest held, then the whole net released; '
        "ase_maud.activation), relax each saddle's two sides to the minima it joins, "
        'and keep the distinct minima and saddles (ase_maud.landscape). Prints what '
        'each attempt did and each saddle with its barriers, draws the '
        'disconnectivity graph (--out) and writes the graph as JSON beside it (--out '
        'with .json). Exit status 0, or 1 if an attempt or descent failed.',
        ['ase-maud saddles cluster.traj --modes 3 --out graph.png',
         'ase-maud saddles net.obj --fix boundary --modes 1 --local 8 --budget 1000',
         'ase-maud saddles dome.traj --modes 0 --mirror   # the snap-through saddle',
         'ase-maud saddles points.xyz --edges edges.txt --dim 2'])
    _add_file(p)
    p.add_argument('--modes', type=_ruled('modes', int), default=2,
                   help='lowest modes climbed, each both ways (default: %(default)s; 0: '
                   'none, the local activations and the path to --partner or --mirror '
                   'alone)')
    p.add_argument('--local', type=_ruled('local', int), default=1,
                   help='local activations after the mode climbs, at points drawn with '
                   '--seed (default: %(default)s)')
    p.add_argument('--budget', type=_ruled('budget', int), default=None,
                   help='force-call equivalents (calls, Hessian-vector products, '
                   'Hessians) of each attempt (default: no bound but --steps)')
    p.add_argument('--seed', type=_ruled('seed', int), default=0,
                   help='seed of the points activated (default: %(default)s)')
    p.add_argument('--window', type=_ruled('window'), default=None, metavar='BARRIER',
                   help='go on in rounds like the first (the next --modes modes, --local '
                   'more points) until --empty-rounds rounds in a row find no new saddle '
                   'whose barrier from the minimum is below BARRIER (energy units; inf: '
                   'any) and that joins it (default: one round)')
    p.add_argument('--empty-rounds', type=_ruled('empty_rounds', int), default=6,
                   metavar='ROUNDS', help='with --window, the rounds in a row that find '
                   'no new saddle before the search stops (default: %(default)s)')
    p.add_argument('--fmax', type=_ruled('fmax'), default=1e-6,
                   help='fmax of every relaxation and climb (default: %(default)s)')
    p.add_argument('--steps', type=_ruled('steps', int), default=1000,
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
                        'one between them (ase_maud.transition.saddle_between)')
    second.add_argument('--mirror', action='store_true',
                        help='the second minimum is the mirror image of the net through '
                        'the plane of its fixed points (a dome and its snap-through; '
                        'ase_maud.transition.reflection), relaxed only if the climbs and '
                        'local activations find no saddle')
    spread = p.add_mutually_exclusive_group()
    spread.add_argument('--workers', type=_ruled('count', int), metavar='N',
                        help='run the climbs and descents on a dask LocalCluster of N '
                        'worker processes on this machine')
    spread.add_argument('--scheduler', metavar='ADDRESS',
                        help='run them on the dask.distributed scheduler at ADDRESS '
                        '(tcp://host:8786: a cluster of machines)')
    _add_net_options(p)
    _add_threads(p, None, 'leave the environment alone')
    p.set_defaults(func=saddles)

    p = _command(
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
    p.add_argument('--sizes', nargs='+', type=_size, metavar='SIZE',
                   help='sizes of every scene (default: suite sizes)')
    p.add_argument('--seeds', nargs='+', type=_ruled('seed', int), default=[0], metavar='K',
                   help='seeds of the starts (default: 0)')
    p.add_argument('--optimizers', nargs='+', choices=OPTIMIZERS,
                   default=list(OPTIMIZERS), metavar='NAME',
                   help=f'of: {", ".join(OPTIMIZERS)} (default: all)')
    p.add_argument('--fmax', nargs='+', type=_ruled('fmax'), default=[1e-3, 1e-6],
                   help='fmax levels of the summary; runs stop at the lowest '
                   '(default: 1e-3 1e-6)')
    p.add_argument('--steps', type=_ruled('steps', int), default=10000,
                   help='step budget of every run (default: %(default)s)')
    p.add_argument('--reference', choices=OPTIMIZERS, default='LBFGS',
                   metavar='NAME', help='optimiser of the reference runs '
                   '(default: %(default)s)')
    p.add_argument('--ref-fmax', type=_ruled('fmax'), default=1e-9,
                   help='fmax of the reference runs (default: %(default)s)')
    p.add_argument('--energy-rtol', type=_ruled('energy_rtol'), default=1e-6,
                   help='relative energy difference from the reference '
                   'beyond which a converged run is in another minimum '
                   '(default: %(default)s)')
    p.add_argument('--out', default='maud-bench',
                   help='output directory (default: %(default)s)')
    p.add_argument('--progress', action=argparse.BooleanOptionalAction,
                   help='progress bar on stderr (default: if it is a tty)')
    _add_threads(p, 1, '1')
    p.set_defaults(func=bench)

    p = _command(
        commands, 'backends', COMMANDS['backends'],
        'Time one energy-and-forces call, and one call with the '
        'nodal stiffness, of every backend on N random points, and its '
        'relative error against the numpy reference. Writes backends.csv, '
        'backends.md and backends.png.',
        ['ase-maud backends --natoms 1000 10000 --backends numba fmm'])
    p.add_argument('--natoms', nargs='+', type=_ruled('count', int),
                   default=[100, 300, 1000, 3000], metavar='N',
                   help='numbers of points (default: 100 300 1000 3000)')
    needs = '; '.join(f'{b.name} needs {", ".join(b.requires)}'
                      for b in map(registry.get, registry.names())
                      if b.requires)
    p.add_argument('--backends', nargs='+', choices=registry.names(),
                   metavar='NAME',
                   help=f'of: {", ".join(registry.names())} (default: all '
                   f"that are installed but auto, which picks one of them; {needs})")
    p.add_argument('--repeats', type=_ruled('count', int), default=3,
                   help='timed calls per point, the best kept '
                   '(default: %(default)s)')
    p.add_argument('--seed', type=_ruled('seed', int), default=0,
                   help='seed of the points (default: %(default)s)')
    p.add_argument('--out', default='maud-bench',
                   help='output directory (default: %(default)s)')
    _add_threads(p, 1, '1')
    p.set_defaults(func=backends)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``ase-maud`` on ``argv`` (default ``sys.argv[1:]``); return the
    exit status (module docstring). Without a command, print the help.
    Bad input, files that cannot be read or written and runs that cannot go
    on (ValueError, OSError, :class:`~ase_maud.MaudError`) are said in one
    line on stderr, status 2. Without a command nothing but argparse is
    imported (``ase-maud --help`` answers at once)."""
    words = sys.argv[1:] if argv is None else list(argv)
    if not COMMANDS.keys() & set(words):
        parser, commands = _top_parser()
        for name, text in COMMANDS.items():
            commands.add_parser(name, help=text)
        parser.parse_args(words)   # --help, or an error
        parser.print_help()
        return 0
    from .monitor import MaudError
    from .threads import pin_threads

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
        return args.func(args)
    except (ValueError, OSError, MaudError) as error:
        print(f'{parser.prog}: error: {_one_line(error)}', file=sys.stderr)
        return 2
    except KeyboardInterrupt as error:   # every output is whole: replaced when complete
        print(f'{parser.prog}: {_one_line(error) if str(error) else "interrupted"}',
              file=sys.stderr)
        return 130
