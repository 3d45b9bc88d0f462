"""``ase-maud relax``: relax a net from a file, or a built-in scene.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ase_maud.cli.options import log_file, net_options

if TYPE_CHECKING:
    pass


def progress_bar(opt, atoms, fmax: float, steps: int):
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


def relax_command(args: argparse.Namespace) -> int:
    """``ase-maud relax``: exit status 0 if converged, else 1."""
    from ase_maud.counting import CallRecorder
    from ase_maud.files.output_paths import StagedTrajectory
    from ase_maud.form.force_density import solve_force_density
    from ase_maud.form.member_forces import (
        describe_result,
        form_result,
        form_warnings,
        write_forces_csv,
    )
    from ase_maud.io.nets import mean_spring_length, net_format, read_net, set_tables, write_net
    from ase_maud.kernel_cache import kernels_cached
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
        atoms = read_net(args.net, load=args.load, **net_options(args))
        label = Path(args.net).name
    set_tables(atoms, loads=args.loads, q=args.q, dim=getattr(args, 'dim', None))
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
