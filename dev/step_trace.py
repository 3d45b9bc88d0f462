"""Where a Maud run's calls go, step by step: per step the energy (and its
height above the run's end), the largest force and its point, whether the
step was accepted or taken back, the step factor gamma, the L-BFGS memory
(pairs kept, cleared when its direction was not downhill), the fraction of
the move the bound kept, the direction's cosine with the forces and the
slope ratio of the step judged (``f_new . s / f_old . s``: 0 at the line
minimum, > 0 short of it, < 0 beyond it); then per scene the calls to each
decade of ``fmax`` and the steps taken back in each::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \\
        python dev/step_trace.py --scenes hub_net:48:0 hanging_net:50 disc:3000 \\
        --out docs/dev/bench/repulsion_cg/trace

A scene is ``name:size[:seed]`` (:func:`ase_maud.scenes.catalogue.build`); ``--model``
is a ``model=`` name of :class:`ase_maud.Maud` seeking a minimum. The trace
is taken by a :class:`~ase_maud.optimize.strategy.Minimise` that records what its
step did (the run's steps are the package's, bit for bit); the unbounded
direction is solved once more per step for the bound's fraction, outside
the calls counted.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ase_maud import Maud
from ase_maud.bench.report import write_csv
from ase_maud.bench.runner import calls_and_cpu
from ase_maud.counting import fresh_copy
from ase_maud.optimize.directions import lbfgs
from ase_maud.optimize.step_length import lengths
from ase_maud.optimize.strategy import Minimise
from ase_maud.scenes.catalogue import build

#: The decades of ``fmax`` (force units) at which the summary counts calls.
DECADES = (10.0, 1.0, 1e-1, 1e-2, 1e-3, 1e-4)


@dataclasses.dataclass(frozen=True)
class TracedMinimise(Minimise):
    """:class:`Minimise` that records one row per step in ``rows``."""

    rows: list[dict[str, Any]] = dataclasses.field(default_factory=list, compare=False)

    def step(self, state, x, merit, forces, noise, local_at):
        last, pairs_before = state.last, len(state.pairs)
        slope = np.nan
        if last is not None:
            s = x - last.x
            slope = float(np.vdot(forces, s) / np.vdot(last.forces, s))
        move = super().step(state, x, merit, forces, noise, local_at)
        here = state.last
        direction = lbfgs(state.solver.solve, here.forces, state.pairs)
        wanted = state.gamma * float(np.linalg.norm(direction))
        magnitude = lengths(forces)
        self.rows.append({
            'step': len(self.rows), 'energy': merit, 'fmax': float(magnitude.max()),
            'fmax_point': int(magnitude.argmax()),
            'accepted': last is None or here is not last,
            'gamma': state.gamma, 'pairs': len(state.pairs),
            'cleared': pairs_before > 0 and not state.pairs,
            'bound_kept': float(np.linalg.norm(move)) / wanted if wanted > 0 else 1.0,
            'cosine': float(np.vdot(direction, here.forces)
                            / (np.linalg.norm(direction) * np.linalg.norm(here.forces))),
            'slope_ratio': slope, 'longest_move': float(lengths(move).max())})
        return move


def trace(spec: str, model: str, fmax: float, steps: int) -> tuple[list[dict], dict]:
    """The rows of a run of ``spec`` (``name:size[:seed]``) and its summary."""
    name, size, *seed = spec.split(':')
    atoms = fresh_copy(build(name, int(size), seed=int(seed[0]) if seed else 0))
    opt = Maud(atoms, model=model, logfile=None)
    if not isinstance(opt.strategy, Minimise):
        raise ValueError(f'{spec}: model={model!r} does not seek a minimum by Minimise')
    opt.strategy = TracedMinimise(**{f.name: getattr(opt.strategy, f.name)
                                 for f in dataclasses.fields(opt.strategy)})
    calls, cpu, done = calls_and_cpu(atoms, opt, fmax, steps)
    rows, end = opt.strategy.rows, atoms.get_potential_energy()
    for row in rows:
        row['above_end'] = row['energy'] - end
    summary = {'scene': spec, 'points': len(atoms), 'model': model, 'converged': done,
               'calls': calls, 'cpu_s': round(cpu, 3), 'energy': end,
               'taken_back': sum(not r['accepted'] for r in rows),
               'cleared': sum(r['cleared'] for r in rows),
               'bound_cuts': sum(r['bound_kept'] < 1 - 1e-9 for r in rows)}
    begin = 0
    for decade in DECADES:   # the first step below each decade, and the steps taken back before it
        reached = next((r['step'] for r in rows if r['fmax'] < decade), len(rows))
        summary[f'to {decade:g}'] = reached
        summary[f'back {decade:g}'] = sum(not r['accepted'] for r in rows[begin:reached])
        begin = reached
    return [{'scene': spec, **row} for row in rows], summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenes', nargs='+', default=['hub_net:48:0', 'hanging_net:50',
                                                        'disc:3000'])
    parser.add_argument('--model', default='springs')
    parser.add_argument('--fmax', type=float, default=1e-4)
    parser.add_argument('--steps', type=int, default=2000)
    parser.add_argument('--out', type=Path)
    args = parser.parse_args()
    trace('hanging_net:4', args.model, 1e-3, 100)   # kernels compiled outside the timing
    rows, summaries = [], []
    for spec in args.scenes:
        steps, summary = trace(spec, args.model, args.fmax, args.steps)
        rows += steps
        summaries.append(summary)
        print(summary, flush=True)
    head = list(summaries[0])
    lines = [f'`python dev/step_trace.py {" ".join(sys.argv[1:])}`: calls to each fmax '
             '(steps from the start; "back": steps taken back since the previous column)', '',
             '| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)]
    lines += ['| ' + ' | '.join(f'{s[k]:.10g}' if isinstance(s[k], float) else str(s[k])
                                for k in head) + ' |' for s in summaries]
    print('\n'.join(lines))
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / 'summary.md').write_text('\n'.join(lines) + '\n')
        write_csv(args.out / 'steps.csv', rows)


if __name__ == '__main__':
    main()
