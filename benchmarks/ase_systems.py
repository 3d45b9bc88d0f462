"""Maud against ASE's optimizers on ASE's usual systems (issue 32), calls
counted at the calculator, CPU time beside.

Systems: :data:`ase_maud.bench.ase_systems.SYSTEMS` (Lennard-Jones clusters
of 7, 13 and 38 atoms from random starts and an LJ O4 molecule; EMT Pt13, an
Au13 icosahedron, bulk Au32, Au8 under a cell filter, O on Au(111) and the
NEB of Au on Al(100), rattled; seeded). Each optimizer relaxes each system
from the same start to ``--fmax`` within ``--steps``; the table gives
calculator calls (summed over a band's images), CPU seconds, the final
energy (a band's highest image), and whether it converged; ``--csv`` writes
every run as a row. ``--maud`` adds Maud variants as
``name=keyword=value,...``. SciPy's L-BFGS-B minimises an energy, so it has
no column for a band.

    python benchmarks/ase_systems.py --seeds 0 1 2 --fmax 0.01 --steps 2000 --csv runs.csv
    python benchmarks/ase_systems.py --basin 20 --systems LJ13 LJ38 --seeds 0 1 2
    python benchmarks/ase_systems.py --basin 20 --race --systems LJ13 LJ38 --seeds 0 1 2
    python benchmarks/ase_systems.py --hops 8 --systems LJ38 --seeds 0 1 2 3 4 5 \
        --optimizers Maud BFGS --csv hops.csv
    python benchmarks/ase_systems.py --systems LJ7 LJ13 LJ38 --seeds $(seq 0 19) \
        --optimizers Maud BFGS --csv lj.csv
"""

from __future__ import annotations

import argparse
import csv

import numpy as np
from ase import Atoms
from ase.optimize import BFGS, FIRE, LBFGS

from ase_maud import Maud
from ase_maud.bench.ase_systems import SYSTEMS
from ase_maud.bench.optimizers import ScipyLBFGSB
from ase_maud.counting import cpu_seconds


class Counted:
    """Counts the calls to the calculators of ``images``' ``calculate``."""

    def __init__(self, images: list[Atoms]):
        self.calls = 0
        for atoms in images:
            calc = atoms.calc
            calc.calculate = self._counting(calc.calculate)

    def _counting(self, inner):
        def calculate(*args, **kwargs):
            self.calls += 1
            return inner(*args, **kwargs)
        return calculate


def scipy_lbfgsb(target, logfile=None):
    """SciPy's L-BFGS-B, made as the table makes an ASE optimizer."""
    return ScipyLBFGSB(target)


def relax(system: str, seed: int, opt, fmax: float, steps: int, **kwargs):
    """(calls, CPU s, final energy, converged: True, False or the error's
    name) of ``opt`` on ``system`` from ``seed``; None for L-BFGS-B on a band."""
    start = SYSTEMS[system](seed)
    if start.band and opt is scipy_lbfgsb:
        return None
    counter = Counted(start.images)
    clock = cpu_seconds()
    try:
        with opt(start.target, logfile=None, **kwargs) as dyn:
            converged = dyn.run(fmax=fmax, steps=steps)
    except Exception as error:   # noqa: BLE001 (a row of the table says it)
        converged = f'{type(error).__name__}'
    cpu = cpu_seconds() - clock
    return counter.calls, cpu, start.energy(), converged


def capped(opt, steps: int, missed: list[int]):
    """``opt`` whose ``run`` takes at most ``steps`` steps (BasinHopping asks
    for 10**8), each local relaxation that does not converge in them noted
    in ``missed``."""
    class Capped(opt):
        def run(self, fmax=0.05, steps_asked=None):
            converged = super().run(fmax=fmax, steps=steps)
            if not converged:
                missed.append(self.nsteps)
            return converged
    return Capped


def basin(system: str, seed: int, opt, hops: int, fmax: float, steps: int):
    """ASE's BasinHopping (kT 1, dr 0.5) of ``hops`` hops with ``opt`` (each
    local relaxation at most ``steps`` steps) from the seeded start, its
    random moves seeded alike: (calls, CPU s, lowest energy, or the error
    that stopped it, and how many local relaxations did not converge)."""
    from ase.optimize.basin import BasinHopping
    atoms = SYSTEMS[system](seed).target
    counter = Counted([atoms])
    missed: list[int] = []
    np.random.seed(seed)   # BasinHopping draws from numpy's global generator
    start = cpu_seconds()
    try:
        with BasinHopping(atoms, temperature=1.0, dr=0.5,
                          optimizer=capped(opt, steps, missed), fmax=fmax,
                          logfile=None, trajectory=None, optimizer_logfile=None) as hopping:
            hopping.run(hops)
            lowest = f'{hopping.get_minimum()[0]:.4f}'
    except Exception as error:   # noqa: BLE001 (a row of the table says it)
        lowest = f'{type(error).__name__}: {error}'
    if missed:
        lowest += f' ({len(missed)} not converged in {steps} steps)'
    return counter.calls, cpu_seconds() - start, lowest


class _Reached(Exception):
    """Stops a race of :func:`race` (its energy reached, or its calls spent)."""


def race(system: str, seed: int, opt, budget: int, target: float, fmax: float,
         steps: int, tolerance: float = 1e-3):
    """ASE's BasinHopping as in :func:`basin` (the same seed, so the same first
    moves), its hops going on until a local relaxation ends at most
    ``tolerance`` above ``target`` (another optimizer's lowest energy) or the
    calls reach ``budget`` (that optimizer's calls): (calls when the target
    was reached or None, calls spent, CPU s, hops, lowest energy)."""
    from ase.optimize.basin import BasinHopping
    atoms = SYSTEMS[system](seed).target
    counter = Counted([atoms])
    relaxed: list[float] = []

    class Racing(capped(opt, steps, [])):
        def run(self, fmax=0.05, steps=None):
            converged = super().run(fmax=fmax)
            relaxed.append(self.optimizable.get_value())
            if relaxed[-1] <= target + tolerance or counter.calls >= budget:
                raise _Reached
            return converged

    np.random.seed(seed)   # BasinHopping draws from numpy's global generator
    start = cpu_seconds()
    try:   # the first relaxation is BasinHopping's construction's
        with BasinHopping(atoms, temperature=1.0, dr=0.5, optimizer=Racing, fmax=fmax,
                          logfile=None, trajectory=None, optimizer_logfile=None) as hopping:
            hopping.run(10**6)
    except _Reached:
        pass
    cpu = cpu_seconds() - start
    lowest = min(relaxed)
    reached = counter.calls if lowest <= target + tolerance else None
    return reached, counter.calls, cpu, len(relaxed) - 1, lowest


def hops(system: str, seed: int, count: int, optimizers: dict, fmax: float, steps: int):
    """Rows (system, seed, hop, optimizer, calls, energy, converged) of
    ``count`` BasinHopping moves (each coordinate moved uniformly within
    +-0.5, as BasinHopping's ``dr=0.5``; drawn by ``RandomState(1000 seed +
    hop)``) from the minimum BFGS reaches from the seeded start, each
    relaxed by every one of ``optimizers`` ({name: (class, keywords)}): the
    same hops, without BasinHopping's chain of them."""
    minimum = SYSTEMS[system](seed).target
    with BFGS(minimum, logfile=None) as dyn:
        dyn.run(fmax=fmax, steps=steps)
    rows = []
    for hop in range(count):
        move = np.random.RandomState(1000 * seed + hop).uniform(-0.5, 0.5, (len(minimum), 3))
        for name, (opt, kwargs) in optimizers.items():
            atoms = minimum.copy()
            atoms.calc = type(minimum.calc)(**minimum.calc.parameters)
            atoms.positions += move
            counter = Counted([atoms])
            with opt(atoms, logfile=None, **kwargs) as dyn:
                converged = dyn.run(fmax=fmax, steps=steps)
            rows.append({'system': system, 'seed': seed, 'hop': hop, 'optimizer': name,
                         'calls': counter.calls,
                         'energy': f'{atoms.get_potential_energy():.6f}',
                         'converged': converged})
            print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[0, 1, 2])
    parser.add_argument('--fmax', type=float, default=0.01)
    parser.add_argument('--steps', type=int, default=2000)
    parser.add_argument('--systems', nargs='+', default=list(SYSTEMS))
    parser.add_argument('--basin', type=int, default=0,
                        help='instead: BasinHopping of this many hops, Maud against BFGS '
                        'or the --optimizers given (each local relaxation at most --steps '
                        'steps)')
    parser.add_argument('--race', action='store_true',
                        help='with --basin: BFGS makes --basin hops; then Maud hops from the '
                        'same seed until it reaches BFGS\'s lowest energy (within 1e-3) or '
                        'spends BFGS\'s calls')
    parser.add_argument('--hops', type=int, default=0,
                        help='instead: this many BasinHopping moves from the minimum BFGS '
                        'reaches from each start, each relaxed by every optimizer (--csv)')
    parser.add_argument('--maud', nargs='*', default=[],
                        help='Maud variants: name=keyword=value,keyword=value')
    parser.add_argument('--optimizers', nargs='+',
                        help='only these columns (default: Maud, its --maud variants, BFGS, '
                        'LBFGS, FIRE, L-BFGS-B)')
    parser.add_argument('--csv', help='write every run (system, seed, optimizer, '
                        'calls, CPU s, energy, converged) to this file')
    args = parser.parse_args()
    optimizers = {'Maud': (Maud, {})}
    for variant in args.maud:
        name, _, settings = variant.partition('=')
        keywords = dict(item.split('=', 1) for item in settings.split(',') if item)
        optimizers[name] = (Maud, {k: _value(v) for k, v in keywords.items()})
    optimizers.update({'BFGS': (BFGS, {}), 'LBFGS': (LBFGS, {}), 'FIRE': (FIRE, {}),
                       'L-BFGS-B': (scipy_lbfgsb, {})})
    if args.optimizers:
        unknown = set(args.optimizers) - set(optimizers)
        if unknown:
            parser.error(f'--optimizers: unknown {sorted(unknown)}; known {list(optimizers)}')
        optimizers = {name: optimizers[name] for name in args.optimizers}
    if args.hops:
        rows = [row for system in args.systems for seed in args.seeds
                for row in hops(system, seed, args.hops, optimizers, args.fmax, args.steps)]
        _write(args.csv, rows)
        return
    if args.basin and args.race:
        print('| system | seed | BFGS: calls, CPU, lowest | Maud: calls to BFGS\'s lowest '
              '(within BFGS\'s calls), hops, CPU, lowest |')
        print('|---|---|---|---|')
        for system in args.systems:
            for seed in args.seeds:
                calls, cpu, lowest = basin(system, seed, BFGS, args.basin, args.fmax, args.steps)
                target = float(lowest.split()[0])
                reached, spent, maud_cpu, count, maud_lowest = race(
                    system, seed, Maud, calls, target, args.fmax, args.steps)
                verdict = (f'{reached} ({reached / calls:.2f}x)' if reached is not None
                           else f'not reached in {spent}')
                print(f'| {system} | {seed} | {calls}, {cpu:.1f} s, {lowest} | {verdict}, '
                      f'{count} hops, {maud_cpu:.1f} s, {maud_lowest:.4f} |', flush=True)
        return
    if args.basin:   # Maud and BFGS unless --optimizers names others (ASE's classes)
        hopping = optimizers if args.optimizers else {
            name: optimizers[name] for name in ('Maud', 'BFGS')}
        if any(kwargs or not isinstance(opt, type) for opt, kwargs in hopping.values()):
            parser.error('--basin: ASE optimizer classes only (no --maud variants, no L-BFGS-B)')
        print('| system | seed | ' + ' | '.join(f'{name}: calls, CPU, lowest'
                                                for name in hopping) + ' |')
        print('|---|---|' + '---|' * len(hopping))
        for system in args.systems:
            for seed in args.seeds:
                cells = [basin(system, seed, opt, args.basin, args.fmax, args.steps)
                         for opt, _ in hopping.values()]
                print(f'| {system} | {seed} | ' + ' | '.join(
                    f'{c}, {t:.1f} s, {e}' for c, t, e in cells) + ' |', flush=True)
        return
    rows = []
    print(f'| system | seed | {" | ".join(optimizers)} |')
    print('|---|---|' + '---|' * len(optimizers))
    for system in args.systems:
        for seed in args.seeds:
            cells = []
            for name, (opt, kwargs) in optimizers.items():
                run = relax(system, seed, opt, args.fmax, args.steps, **kwargs)
                if run is None:
                    cells.append('n/a')
                    continue
                calls, cpu, energy, converged = run
                rows.append({'system': system, 'seed': seed, 'optimizer': name,
                             'calls': calls, 'cpu_s': f'{cpu:.3f}',
                             'energy': f'{energy:.6f}', 'converged': converged})
                mark = (f' ({converged})' if isinstance(converged, str)
                        else '' if converged else ' (no)')
                cells.append(f'{calls}{mark}, {cpu:.2f} s, {energy:.4f}')
            print(f'| {system} | {seed} | ' + ' | '.join(cells) + ' |', flush=True)
    _write(args.csv, rows)


def _write(path: str | None, rows: list[dict]) -> None:
    """``rows`` as CSV to ``path`` (nothing if None)."""
    if path:
        with open(path, 'w', newline='') as file:
            writer = csv.DictWriter(file, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


if __name__ == '__main__':
    main()
