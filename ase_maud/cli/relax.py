"""``ase-maud relax``: relax a net from a file, or a built-in scene.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ase_maud.cli.options import log_file, net_options

if TYPE_CHECKING:
    pass


def convergence_share(first: float, now: float, goal: float) -> float:
    """How far a run has come from its first fmax ``first`` to the ``goal``,
    in log fmax: ``log(first / now) / log(first / goal)``, in [0, 1] (1 at
    or below the goal; 0 at or above the start)."""
    if now <= goal or first <= goal:
        return 1.0
    if now >= first:
        return 0.0
    return math.log(first / now) / math.log(first / goal)


def progress_bar(opt, atoms, fmax: float, steps: int):
    """A tqdm bar on stderr of the optimizer ``opt``'s way to convergence:
    the share of the way from the first fmax to ``fmax`` in log fmax
    (:func:`convergence_share`, never going back), with the step count out of
    ``steps``, fmax against its goal and the energy; its rate and time left
    are those of that share, not of the step budget."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from tqdm import tqdm

    bar = tqdm(total=1000, file=sys.stderr, dynamic_ncols=True,
               bar_format='{l_bar}{bar}| [{elapsed}<{remaining}]{postfix}')
    first = []

    def advance():
        now = float((atoms.get_forces()**2).sum(axis=1).max() ** 0.5)
        if not first:
            first.append(now)
        share = convergence_share(first[0], now, fmax)
        bar.set_postfix_str(f'step {opt.nsteps}/{steps}, fmax {now:.3g} (goal {fmax:.3g}), '
                            f'energy {atoms.get_potential_energy():.10g}', refresh=False)
        bar.update(max(0, round(1000 * share) - bar.n))   # the bar never goes back

    opt.attach(advance)
    return bar


def relax_command(args: argparse.Namespace) -> int:
    """``ase-maud relax``: exit status 0 if converged, else 1."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.counting import CallRecorder
    from ase_maud.files.output_paths import StagedTrajectory
    from ase_maud.form.force_density import solve_force_density
    from ase_maud.form.member_forces import (
        describe_result,
        form_result,
        form_warnings,
        write_forces_csv,
    )
    from ase_maud.io.net_writer import write_net
    from ase_maud.io.nets import mean_spring_length, net_format, read_net, set_tables
    from ase_maud.optimize.maud import Maud
    from ase_maud.physics.topology import free_point_loads
    from ase_maud.scenes.catalogue import build

    if args.net is None:
        atoms = build(args.scene, args.size, seed=args.seed,
                      **{k: v for k, v in (('a', args.a), ('Q', args.Q)) if v is not None})
        if args.load is not None:
            atoms.calc.set(loads=free_point_loads(atoms, args.load))
        label = args.scene
    else:
        atoms = read_net(args.net, **net_options(args))
        label = Path(args.net).name
    set_tables(atoms, loads=args.loads, q=args.q, dim=getattr(args, 'dim', None))
    faces = atoms.info.pop('faces', None)   # for --out, not in every trajectory frame
    a, springs = atoms.calc.parameters['a'], atoms.calc.parameters.get('springs', ())
    share = (f' ({a / mean_spring_length(atoms.positions, springs):.3g} x the mean spring '
             'length at the start)' if a else ' (the force-density equilibrium: no '
             'repulsion)') if len(springs) else ''
    if a == 0:
        solve_force_density(atoms)   # Maud then has nothing left to do
    start = atoms.positions.copy()
    progress = (sys.stderr.isatty() if args.progress is None else args.progress) \
        and not args.quiet and args.log != '-'
    logfile = log_file(args.log) or (None if progress or args.quiet else '-')
    with CallRecorder(atoms.calc) as recorder, StagedTrajectory(args.traj) as staged, \
            Maud(atoms, model=args.model, method=args.method, logfile=logfile,
                 trajectory=staged.trajectory,
                 divergence_factor=args.divergence_factor) as opt:
        opt.attach(staged.keep)   # the trajectory replaces --traj at its first frame
        bar = progress_bar(opt, atoms, args.fmax, args.steps) if progress else None
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
    if faces is not None:
        atoms.info['faces'] = faces
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
          f'{describe_result(result, repulsion=a > 0)}; {written}')
    struts = len(atoms.calc.potential.compressed)
    if struts and a > 0:
        print(f'ase-maud: note: {struts} members are in compression (q < 0), so the energy '
              'is not convex: the form found is an equilibrium (a stationary point of the '
              'energy), not a minimum', file=sys.stderr)
    for warning in form_warnings(atoms, start, result) if args.net is not None else ():
        print(f'ase-maud: warning: {warning}', file=sys.stderr)
    return 0 if converged else 1
