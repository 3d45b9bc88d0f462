"""``ase-maud bench`` and ``ase-maud backends``: the benchmarks.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    pass


def bench_command(args: argparse.Namespace) -> int:
    """``ase-maud bench``: exit status 0, or 130 if interrupted."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.bench.suite import benchmark
    from ase_maud.scenes.catalogue import SUITES, scene_sizes

    starts = [(scene, size, seed)
              for scene, size in scene_sizes(args.scenes, args.sizes, SUITES[args.suite])
              for seed in args.seeds]
    show_command = sys.stderr.isatty() if args.progress is None else args.progress
    interrupted = benchmark(
        starts, args.optimizers, Path(args.out), levels=args.fmax, steps=args.steps,
        reference=args.reference, ref_fmax=args.ref_fmax,
        energy_rtol=args.energy_rtol, progress=show_command, argv=args.argv)
    print(f'results in {args.out}/')
    return 130 if interrupted else 0


def backends_command(args: argparse.Namespace) -> int:
    """``ase-maud backends``: exit status 0."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.bench.backends import write_backends_report

    print(write_backends_report(Path(args.out), args.natoms, args.backends,
                                repeats=args.repeats, seed=args.seed,
                                argv=args.argv))
    print(f'results in {args.out}/')
    return 0
