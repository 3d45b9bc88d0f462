"""Compare variants of Maud's step rules on the scene suite, in force calls.

Each variant (a JSON dict of Maud keyword arguments, over `model="nodal"`: the
specification's step, whose rules these are) runs from the same starts
as FIRE, BFGS and LBFGS; the table gives, per scene, the median over seeds of
Maud's calls to fmax 1e-6 divided by the fewest calls of the three. This is
how the defaults in docs/optimizer.md were chosen. Run with one thread:

    NUMBA_NUM_THREADS=1 python dev/tune_maud.py '{}' '{"gamma_max": 1.5}'
"""

import argparse
import json

import numpy as np
from ase.optimize import BFGS, FIRE, LBFGS

from ase_maud import Maud, MaudError
from ase_maud.counting import CallRecorder
from ase_maud.scenes.catalogue import SUITE, build

EXTRA = [('ring', 50), ('chain', 30), ('all_pairs', 12), ('random_graph', 40),
         ('net3d', 8)]


def calls_to_converge(name, size, seed, opt, kwargs, fmax, steps):
    """Calculator calls to reach ``fmax`` (inf if not reached)."""
    atoms = build(name, size, seed=seed)
    try:
        with CallRecorder(atoms.calc) as recorder, \
                opt(atoms, logfile=None, **kwargs) as dyn:
            converged = dyn.run(fmax=fmax, steps=steps)
    except MaudError:
        converged = False
    return len(recorder.samples) if converged else np.inf


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('variants', nargs='*', default=['{}'],
                        help='JSON dicts of Maud keyword arguments')
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    parser.add_argument('--fmax', type=float, default=1e-6)
    parser.add_argument('--steps', type=int, default=5000)
    args = parser.parse_args()
    scenes = SUITE + EXTRA
    best = {(name, size, seed): min(
        calls_to_converge(name, size, seed, opt, {}, args.fmax, args.steps)
        for opt in (FIRE, BFGS, LBFGS))
        for name, size in scenes for seed in args.seeds}
    print('variant | median | worst | ' + ' | '.join(
        f'{name} {size}' for name, size in scenes))
    for text in args.variants:
        kwargs = {'model': 'nodal', **json.loads(text)}  # the nodal step's rules
        per_scene = []
        for name, size in scenes:
            per_scene.append(np.median([
                calls_to_converge(name, size, seed, Maud, kwargs, args.fmax,
                                  args.steps) / best[name, size, seed]
                for seed in args.seeds]))
        print(f'{text} | {np.median(per_scene):.2f} | {max(per_scene):.2f} | '
              + ' | '.join(f'{r:.2f}' for r in per_scene), flush=True)


if __name__ == '__main__':
    main()
