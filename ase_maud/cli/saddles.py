"""``ase-maud saddles``: the landscape around a net's minimum.
"""

from __future__ import annotations

import argparse
import contextlib
from typing import TYPE_CHECKING

from ase_maud.cli.options import graph_json, net_options

if TYPE_CHECKING:
    from ase import Atoms


def saddles_command(args: argparse.Namespace) -> int:
    """``ase-maud saddles``: the net relaxed to a minimum, its landscape
    (:func:`ase_maud.saddles.landscape.landscape`) printed, drawn (--out) and written
    as JSON beside the picture; exit status 0 (1 if a climb or descent
    failed)."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    import json

    from ase_maud.files.atomic_replace import replace_text, replace_with
    from ase_maud.form.pictures import save_disconnectivity
    from ase_maud.io.nets import read_net
    from ase_maud.optimize.maud import Maud
    from ase_maud.saddles.landscape import landscape

    atoms = read_net(args.file, index=args.frame, **net_options(args))
    Maud(atoms, logfile=None).run(fmax=args.fmax, steps=args.steps)
    partner = mirror_partner(args, atoms)
    with dask_client(args.workers, args.scheduler) as client:
        found = landscape(atoms, modes=args.modes, fmax=args.fmax, steps=args.steps,
                          client=client, local=args.local, budget=args.budget,
                          seed=args.seed, partner=partner, mirror=args.mirror,
                          window=args.window, empty_rounds=args.empty_rounds,
                          sweep=args.sweep)
    print(found.search.report())
    energies = [m.get_potential_energy() for m in found.minima]
    barriers = [s.get_potential_energy() for s in found.saddles]
    for s, ((i, j), (up_i, up_j)) in enumerate(zip(found.joins, found.barriers(),
                                                     strict=True)):
        print(f'saddle {s}: energy {barriers[s]:.10g}, ' + (
            f'joins minimum {i} (barrier {up_i:.6g}) and minimum {j} (barrier {up_j:.6g})'
            if i != j else f'both sides descend to minimum {i} (barriers {up_i:.6g} and '
            f'{up_j:.6g}): a saddle on a path from that minimum back to itself'))
    print(f'{counted(len(energies), "minimum", "minima")} (lowest {min(energies):.10g}), '
          f'{counted(len(barriers), "saddle")}, '
          f'{counted(found.failed, "failed attempt or descent", "failed attempts or descents")}'
          f'; {args.out} and {graph_json(args)}')
    replace_with(args.out, lambda temporary: save_disconnectivity(
        energies, barriers, found.joins, temporary))
    replace_text(graph_json(args), json.dumps(found.todict()))
    return 1 if found.failed else 0


def counted(count: int, one: str, many: str | None = None) -> str:
    """``count`` and the noun in its number: '1 minimum', '2 minima', '0 saddles'."""
    return f'{count} {one if count == 1 else many or one + "s"}'


def mirror_partner(args: argparse.Namespace, minimum: Atoms) -> Atoms | None:
    """The second minimum of ``ase-maud saddles`` given as --partner (None
    without): the points of that file (its last frame, read as the net is)
    on the net of ``minimum``, relaxed by Maud to --fmax (--mirror asks the
    search for the mirror image instead). A ValueError names a --partner
    file whose points are not the net's, or one that does not relax."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.counting import fresh_copy
    from ase_maud.io.nets import read_net
    from ase_maud.optimize.maud import Maud

    if args.partner is None:
        return None
    read = read_net(args.partner, **net_options(args))
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
def dask_client(workers: int | None, scheduler: str | None):
    """A dask.distributed Client: of a LocalCluster of ``workers`` processes
    (one thread each), or of the scheduler at ``scheduler``; None for
    neither. A ValueError if dask.distributed is not installed."""
    if workers is None and scheduler is None:
        yield None
        return
    try:
        # Imported when the command runs, so that ase-maud --help answers at once.
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
