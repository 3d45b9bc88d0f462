"""The size of a run's trajectory against ASE's own for the same frames:
``ase-maud relax`` of a 100 x 100 net (10^4 points) for ``--steps`` steps,
its trajectory's bytes, and the bytes of the same frames (positions, energy,
forces, constraints) written by ASE's Trajectory with a SinglePointCalculator.
Printed and saved (``--out``, Markdown)::

    OMP_NUM_THREADS=1 python benchmarks/trajectory_size.py --out docs/dev/bench/trajectory_size.md

Sizes do not depend on the machine's load; the run's time does, and is not
reported.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import tempfile
from pathlib import Path

from ase.calculators.singlepoint import SinglePointCalculator
from ase.io.trajectory import Trajectory

from ase_maud.cli.command import main as ase_maud

#: Issue 55's goal: at most this much larger than ASE's own.
GOAL = 0.05


def measure(size: int, steps: int, folder: Path) -> tuple[int, int, int]:
    """(frames, bytes of ase-maud's trajectory, bytes of ASE's of the same frames)."""
    ours = folder / 'run.traj'
    ase_maud(['relax', '--scene', 'net2d', '--size', str(size), '--steps', str(steps),
              '--fmax', '1e-12', '--quiet', '--traj', str(ours)])
    theirs = folder / 'ase.traj'
    with Trajectory(ours) as frames, Trajectory(theirs, 'w') as out:
        count = len(frames)
        plain = frames[0].copy()   # one Atoms moved along, as ASE's optimizers write it
        for frame in frames:
            plain.positions = frame.positions
            plain.calc = SinglePointCalculator(plain, energy=frame.get_potential_energy(),
                                               forces=frame.get_forces(apply_constraint=False))
            out.write(plain)
    return count, ours.stat().st_size, theirs.stat().st_size


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    for flag, kind, default, meaning in (
            ('--size', int, 100, 'points along a side of the net'),
            ('--steps', int, 34, "steps of the run: one frame more"),
            ('--out', Path, None, 'the Markdown table (default: printed only)')):
        parser.add_argument(flag, type=kind, default=default, help=meaning)
    args = parser.parse_args(argv)
    if args.out is not None and args.out.exists():
        parser.error(f'--out {str(args.out)!r} exists: give a new file')
    with tempfile.TemporaryDirectory() as folder:
        count, ours, theirs = measure(args.size, args.steps, Path(folder))
    excess = ours / theirs - 1
    report = '\n'.join([
        f'# Trajectory size: ase-maud relax against ASE, {args.size ** 2} points', '',
        f'{datetime.date.today()}: `python benchmarks/trajectory_size.py '
        f'{" ".join(sys.argv[1:])}`', '',
        '| frames | ase-maud (bytes) | ASE, same frames (bytes) | larger by | goal |',
        '|---|---|---|---|---|',
        f'| {count} | {ours} | {theirs} | {100 * excess:.1f} % | '
        f'{100 * GOAL:.0f} % ({"met" if excess <= GOAL else "NOT met"}) |']) + '\n'
    sys.stdout.write(report)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with open(args.out, 'x') as handle:   # an existing file is never replaced
            handle.write(report)


if __name__ == '__main__':
    main()
