"""Calculator property requests per Maud step (each one runs ASE's change
detection): docs/dev/benchmarks.md quotes the output::

    python dev/requests_per_step.py chain 20
"""

from __future__ import annotations

import argparse
from collections import Counter

from ase.calculators.calculator import Calculator

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('scene')
    parser.add_argument('size', type=int)
    parser.add_argument('--fmax', type=float, default=1e-6)
    args = parser.parse_args()
    counts: Counter = Counter()
    get_property = Calculator.get_property

    def counted(self, name, atoms=None, allow_calculation=True):
        counts[name] += 1
        return get_property(self, name, atoms, allow_calculation)

    Calculator.get_property = counted
    atoms = build(args.scene, args.size, seed=0)
    with Maud(atoms, logfile=None) as opt:
        opt.run(fmax=args.fmax)
    per_step = {name: round(n / opt.nsteps, 2) for name, n in counts.items()}
    print(f'{args.scene} {args.size}: {opt.nsteps} steps, '
          f'{sum(counts.values()) / opt.nsteps:.2f} requests per step {per_step}')


if __name__ == '__main__':
    main()
