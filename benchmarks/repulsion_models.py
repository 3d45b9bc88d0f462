"""Maud's stiffness models against SciPy's L-BFGS-B on the scenes where the
repulsion, not the springs, sets the shape: free neighbour graphs, clusters,
the dense compas meshes (benchmarks/compas_nets.py's nets, boundary fixed) and the
hub net. Calls (Hessian-vector products counted as one call each, beside),
CPU seconds and the energy reached, to ``--fmax`` (in ``Q a``), one thread::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python benchmarks/repulsion_models.py --out docs/dev/bench/repulsion

A scene is ``name:size[:seed]`` (:func:`ase_maud.scenes.catalogue.build`, seed 0 by default) or
``compas:<sample>`` (a compas sample mesh); a variant is ``L-BFGS-B``, a
``model=`` name of :class:`ase_maud.Maud` (``near``: the package's
near-field model, :mod:`ase_maud.optimize.models.near`), ``near-all``: that model with
the repulsion block of every sprung pair (``per_point=None``, the
prototype's pairs), or ``near-lu`` / ``near-lu-<k>``: the factorised
:class:`ase_maud.optimize.models.near_lu.NearLUModel`, the same ``P`` less the
springs model's shifts, factorised at every step or kept for ``k`` steps (it
measured no CPU win over the springs model, docs/dev/benchmarks.md, so it is no
``model=`` name). ``H v`` counts Hessian-vector products (each
about a force call, none here); ``P v`` the near-field model's sparse
products with its ``P`` (``work.near_products``, O(pairs) each), which the
CPU seconds hold but the calls do not.
"""

from __future__ import annotations

import argparse
import datetime
import sys
from pathlib import Path

from ase_maud import Maud
from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.bench.report import write_csv
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.counting import fresh_copy
from ase_maud.optimize.models.near import NearModel
from ase_maud.optimize.models.near_lu import NearLUModel
from ase_maud.scenes.catalogue import build

sys.path.insert(0, str(Path(__file__).parent))   # benchmarks/compas_nets.py's nets, in scene()

SCENES = ['neighbour_graph:1000', 'neighbour_graph:2000', 'all_pairs:300',
          'compas:mesh_100_faces.json', 'compas:mesh_110_faces.json',
          'compas:faces_big.obj', 'hub_net:48']
VARIANTS = ['L-BFGS-B', 'springs', 'near', 'near-all', 'global', 'nodal', 'near-lu',
            'near-lu-10']


def scene(spec: str):
    """The start of ``spec`` and its unit of force ``Q a`` (``a`` of a compas net)."""
    name, size, *seed = spec.split(':')
    if name == 'compas':
        from compas_nets import net, sample_dir
        atoms, a, _ = net(sample_dir() / size)
        return atoms, a
    return build(name, int(size), seed=int(seed[0]) if seed else 0), 1.0


def run(start, unit: float, variant: str, fmax: float, steps: int) -> dict:
    atoms = fresh_copy(start)
    hvp = pv = 0
    if variant in OPTIMIZERS and variant != 'Maud':
        optimiser = OPTIMIZERS[variant](atoms)
    elif variant == 'near-all':
        optimiser = Maud(atoms, model=NearModel(per_point=None), logfile=None)
    elif variant.startswith('near-lu'):
        reuse = int(variant.removeprefix('near-lu').lstrip('-') or 1)
        optimiser = Maud(atoms, model=NearLUModel(reuse=reuse), logfile=None)
    else:
        optimiser = Maud(atoms, model=variant, logfile=None)
    calls, cpu, done = calls_and_cpu(atoms, optimiser, fmax * unit, steps)
    if isinstance(optimiser, Maud):
        hvp, pv = optimiser.model.work.total, optimiser.model.work.near_products
    return {'points': len(atoms), 'variant': variant, 'converged': done, 'calls': calls,
            'hvp': hvp, 'pv': pv, 'cpu_s': round(cpu, 3), 'energy': atoms.get_potential_energy()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=SCENES)
    parser.add_argument('--variants', nargs='+', default=VARIANTS)
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    warm = build('hanging_net', 4)
    for variant in args.variants:   # kernels compiled or loaded outside the timing
        run(warm, 1.0, variant, 1e-3, 100)
    rows = []
    for spec in args.scenes:
        start, unit = scene(spec)
        for variant in args.variants:
            rows.append({'scene': spec, **run(start, unit, variant, args.fmax, args.steps)})
            print(rows[-1], flush=True)
    lines = [f'Measured {datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, one thread, '
             f'fmax {args.fmax:g} Q a: `python benchmarks/repulsion_models.py '
             f'{" ".join(sys.argv[1:])}`', '',
             '| scene | N | variant | converged | calls + H v | P v | CPU s | calls / L-BFGS-B '
             '| CPU / L-BFGS-B | energy |', '|---|---|---|---|---|---|---|---|---|---|']
    for row in rows:
        peer = next((r for r in rows if r['scene'] == row['scene']
                     and r['variant'] == 'L-BFGS-B'), row)
        total = row['calls'] + row['hvp']
        hvp = f' + {row["hvp"]}' if row['hvp'] else ''
        lines.append(f'| {row["scene"]} | {row["points"]} | {row["variant"]} | '
                     f'{row["converged"]} | {row["calls"]}{hvp} | {row["pv"]} | '
                     f'{row["cpu_s"]:.2f} | '
                     f'{total / peer["calls"]:.2f} | {row["cpu_s"] / peer["cpu_s"]:.2f} | '
                     f'{row["energy"]:.10g} |')
    print('\n'.join(lines))
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'summary.md').write_text('\n'.join(lines) + '\n')
        write_csv(args.out / 'runs.csv', rows)


if __name__ == '__main__':
    main()
