"""Hostile inputs, class by class: what each gets now.

Prints a markdown table (docs/hard_cases.md): per class, the inputs tried
and how many got a correct answer, a ValueError, a MaudError, or anything
else (a defect: a raw TypeError, a non-finite position, a stale or wrong
result). Run with the threads pinned::

    NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python dev/hostile_sweep.py

The SIGKILL class is tests/optimize/test_resume.py (5 kills at seeded moments).

``--issue-52`` runs issue 52's classes alone (special files and links as
outputs, mesh inputs, round trips, arguments as written, the cases ASE's
BFGS converges on, the last raw tracebacks), each case judged as correct,
a clear error, data lost, silently wrong, a hang, a false error or a raw
traceback (:func:`judged`); the command-line cases run in subprocesses with
a generous timeout, so a hang is counted, not waited on.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import json
import os
import sys
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path
from unittest import mock

import numpy as np
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron
from ase.constraints import FixAtoms, FixBondLength, FixedLine, FixedPlane, Hookean
from ase.filters import Filter, FrechetCellFilter, StrainFilter, UnitCellFilter
from ase.io import read
from ase.md.verlet import VelocityVerlet
from ase.optimize import BFGS
from ase.optimize.basin import BasinHopping

from ase_maud import Maud, MaudCalculator, MaudError
from ase_maud.bench.doubles import PoisonedCalculator
from ase_maud.bench.hard_inputs import (  # the tests' own cases
    BROKEN,
    DAMAGES,
    relaxed_in_a_cell_filter,
    wrong_results_of_threads,
)
from ase_maud.checks import RULES
from ase_maud.cli.command import main as main_cli
from ase_maud.files.atomic_replace import LEFTOVER_SECONDS
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.physics.topology import fixed_atoms
from ase_maud.scenes.catalogue import build

#: Maud's numeric keywords (RULES holds the rule of each).
KEYWORDS = [name for name in inspect.signature(Maud).parameters
            if name in RULES and not RULES[name].choices]

HOSTILE = [0, 0.0, -1, -1.0, np.nan, np.inf, -np.inf, None, 'x', '1', True, False,
           [1.0], 1e-300, 1e300, 10**400, 0.5, 2]
FMAX = [0, -1, np.nan, np.inf, -np.inf, None, 'x', True, [0.1], 1e-300, 1e300, 1e-6]
STEPS = [-1, np.nan, 1.5, 'x', None, True, np.inf, 10**400, 0, 5, 1e3, 2000]


def outcome(run) -> str:
    """'correct', 'ValueError', 'MaudError' or 'other: ...' for ``run()``,
    which returns True for a correct answer."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            return 'correct' if run() else 'other: wrong answer'
    except (ValueError, MaudError) as error:
        kind = 'MaudError' if isinstance(error, MaudError) else 'ValueError'
        return f'{kind}: {error}' if str(error) else f'other: {kind} without a message'
    except Exception as error:   # noqa: BLE001 (counted as a defect)
        return f'other: {type(error).__name__}: {error}'


def minimum():
    atoms = build('ring', 8, seed=1)
    with BFGS(atoms, logfile=None) as opt:
        opt.run(fmax=1e-9, steps=5000)
    return atoms.get_potential_energy()


E_RING = minimum()


def relax_ring(fmax=1e-6, steps=2000, **keywords):
    """A correct answer: finite positions, and converged to the ring's
    minimum, or honestly not converged (fmax above the request)."""
    atoms = build('ring', 8, seed=1)
    try:
        with Maud(atoms, **{'logfile': None, **keywords}) as opt:
            converged = opt.run(fmax=fmax, steps=steps)
    finally:
        assert np.isfinite(atoms.positions).all()
    largest = np.linalg.norm(atoms.get_forces(), axis=1).max()
    if converged != (largest < fmax):
        return False
    energy = atoms.get_potential_energy()
    return not converged or fmax > 1e-3 or abs(energy - E_RING) < 1e-8 * E_RING


def run_arguments():
    return [(lambda f=f, s=s: relax_ring(f, s)) for f in FMAX for s in STEPS]


def keywords():
    names = [n for n in KEYWORDS if n not in ('fmax', 'steps')] + ['model', 'method', 'target']
    return [(lambda n=n, v=v: relax_ring(**{n: v})) for n in names for v in HOSTILE]


def files(directory: Path):
    cases = [('logfile', 1), ('logfile', True), ('logfile', 3.5), ('trajectory', 2),
             ('restart', object()), ('trajectory', directory / 'missing' / 'x.traj'),
             ('logfile', directory / 'missing' / 'x.log'),
             ('restart', directory / 'missing' / 'x.json'), ('restart', directory),
             ('trajectory', ''), ('append_trajectory', 'yes'), ('append_trajectory', None),
             ('trajectory', directory / 'ok.traj'), ('restart', directory / 'ok.json'),
             ('logfile', directory / 'ok.log')]
    return [(lambda n=n, v=v: relax_ring(**{n: v})) for n, v in cases]


def small_scales():
    """A move of a thousandth of ``a`` changes the energy at every scale."""
    def moved(a):
        atoms = build('ring', 8, seed=1, a=a, Q=1.0)
        before = atoms.get_potential_energy()
        atoms.positions[3, 0] += 1e-3 * a
        return atoms.get_potential_energy() != before
    return [(lambda a=a: moved(a)) for a in (1e-12, 1e-10, 1e-6, 1.0, 1e6, 1e12)]


def non_finite(directory: Path):
    def case(scene, what, value, call):
        if scene == 'emt':
            atoms = Icosahedron('Cu', 2)
            atoms.rattle(0.05, seed=1)
            inner = EMT()
        else:
            atoms = build('hanging_net', 5, seed=1)
            inner = MaudCalculator(**atoms.calc.parameters)
        atoms.calc = PoisonedCalculator(inner, call, what, value)
        traj = directory / f'{scene}{what}{value}{call}.traj'
        try:
            with Maud(atoms, logfile=None, trajectory=traj) as opt:
                opt.run(fmax=1e-6)
        finally:
            assert np.isfinite(atoms.positions).all()
            if traj.exists() and traj.stat().st_size:
                assert all(np.isfinite(f.get_forces()).all() for f in read(traj, ':'))
        return False   # a run that ends without an error missed the value
    return [(lambda c=c: case(*c)) for c in
            [(s, w, v, k) for s in ('emt', 'maud') for w in ('energy', 'forces')
             for v in (np.nan, np.inf, -np.inf) for k in (1, 2, 4, 8)]]


def extreme_scales():
    """H2's class: a Maud relaxation at extreme ``a`` and a pair 1e-110 apart."""
    def relax(a):
        atoms = build('ring', 8, seed=1, a=a)
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-6 * a, steps=500)
        return (np.isfinite(atoms.positions).all()
                and abs(atoms.get_potential_energy() / a**2 - E_RING) < 1e-7 * E_RING)

    def close(d):
        atoms = build('all_pairs', 6, seed=1)
        atoms.positions[0] = 0.0
        atoms.positions[1] = [d, 0, 0]
        energy, forces = atoms.get_potential_energy(), atoms.get_forces()
        return np.isfinite(energy) and np.isfinite(forces).all()
    return ([(lambda a=a: relax(a)) for a in (1e-105, 1e-60, 1e60, 1e100)]
            + [(lambda d=d: close(d)) for d in (1e-110, 1e-200, 1e-300)])


def fmm_near_pairs():
    """H2's class: the fmm backend with a pair closer than 1e-12 of the box."""
    def case(d):
        atoms = build('all_pairs', 40, seed=1)
        atoms.positions[0] = 0.0
        atoms.positions[1] = [d, 0, 0]
        reference = atoms.copy()
        reference.calc = MaudCalculator(**{**atoms.calc.parameters, 'backend': 'numpy'})
        atoms.calc = MaudCalculator(**{**atoms.calc.parameters, 'backend': 'fmm'})
        return np.allclose(atoms.get_forces(), reference.get_forces(), rtol=1e-6,
                           atol=1e-6 * np.abs(reference.get_forces()).max())
    return [(lambda d=d: case(d)) for d in (1e-6, 1e-10, 1e-13, 1e-15)]


def planar_drivers():
    def hop(name):
        atoms = build(name, seed=2)
        np.random.seed(3)
        with BasinHopping(atoms, temperature=1.0, dr=0.5, optimizer=Maud, fmax=1e-4,
                          logfile=None, optimizer_logfile=None, trajectory=None,
                          local_minima_trajectory=None) as hopping:
            hopping.run(3)
        return np.ptp(atoms.positions[:, 2]) == 0

    def md(name):
        atoms = build(name, seed=2)
        atoms.set_momenta(np.random.default_rng(1).normal(size=(len(atoms), 3)))
        with VelocityVerlet(atoms, timestep=0.01) as dyn:
            dyn.run(20)
        return np.ptp(atoms.positions[:, 2]) == 0
    names = ('ring', 'net2d', 'all_pairs2d')
    return [(lambda n=n: hop(n)) for n in names] + [(lambda n=n: md(n)) for n in names]


def unclear_errors():
    """Bad inputs of the scene builders and the calculator: a ValueError
    whose message names the input is the answer."""
    calls = [lambda: build('ring', 'x'), lambda: build('ring', np.nan),
             lambda: build('ring', 2), lambda: build('ring', 8, seed='x'),
             lambda: build('ring', 8, seed=-1), lambda: build('ring', 8, a='x'),
             lambda: build('ring', 8, b=1), lambda: build('molecule', 'XYZ'),
             lambda: build('nope'), lambda: MaudCalculator(a=0),
             lambda: MaudCalculator(springs=[[0, 0]]), lambda: MaudCalculator(dim=4),
             lambda: MaudCalculator(backend='cuda')]
    return calls


# -- the user's files, re-runs, restarts and odd inputs ---------------------------

def bfgs_energy(atoms):
    """The energy BFGS reaches from ``atoms``' positions (an independent answer)."""
    reference = atoms.copy()
    reference.calc = MaudCalculator(**atoms.calc.parameters)
    with BFGS(reference, logfile=None) as opt:
        opt.run(fmax=1e-9, steps=5000)
    return reference.get_potential_energy()


def same_minimum(atoms, rtol=1e-8):
    """``atoms`` at BFGS's minimum from where they are, or at a lower one
    whose Hessian (on the free coordinates) is positive."""
    energy, expected = atoms.get_potential_energy(), bfgs_energy(atoms)
    if abs(energy - expected) <= rtol * abs(expected):
        return True
    free = np.flatnonzero(~fixed_atoms(atoms))
    dofs = (3 * free[:, None] + np.arange(atoms.calc.dim)).ravel()
    hessian = atoms.calc.get_property('hessian', atoms)
    return energy < expected and np.linalg.eigvalsh(hessian[np.ix_(dofs, dofs)]).min() > 0


def users_files(directory: Path):
    """Write-back over the file read, and a write whose replace fails (a full
    disk): the user's file is whole and as it was (or as written)."""
    def over_itself(kind, seed):
        path = directory / f'own{seed}.{kind}'
        write_net(path, build('hanging_net', 6, seed=seed))
        atoms = read_net(path)
        atoms.positions += np.random.default_rng(seed).normal(scale=0.1, size=(36, 3))
        write_net(path, atoms, like=path)
        return np.allclose(read_net(path).positions, atoms.positions, rtol=0, atol=1e-12)

    def full_disk(kind, seed):
        path = directory / f'disk{seed}.{kind}'
        write_net(path, build('hanging_net', 6, seed=seed))
        before = path.read_bytes()
        atoms = read_net(path)
        atoms.positions += 1.0
        with mock.patch('ase_maud.files.atomic_replace.os.replace',
                        side_effect=OSError(28, 'full')):
            try:
                write_net(path, atoms, like=path)
            except OSError:
                pass
        return path.read_bytes() == before
    kinds = ('obj', 'json', 'traj')
    return ([(lambda k=k, s=s: over_itself(k, s)) for k in kinds for s in range(3)]
            + [(lambda k=k, s=s: full_disk(k, s)) for k in kinds for s in range(3)])


def second_runs():
    """A second run of one optimiser after the atoms moved, after ``calc.set``
    between runs, and after ``calc.set`` by an observer in mid-run."""
    def moved(seed):
        atoms = build('random_graph', 12, seed=seed)
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-6)
            atoms.rattle(np.random.default_rng(seed).uniform(0.05, 0.5), seed=seed)
            return opt.run(fmax=1e-6) and same_minimum(atoms)

    def changed(seed):
        atoms = build('hanging_net', 5, seed=seed)
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-6)
            atoms.calc.set(a=[2.0, 5.0, 10.0][seed % 3])
            return opt.run(fmax=1e-6) and same_minimum(atoms)

    def observer(seed):
        atoms = build('hanging_net', 5, seed=seed)
        with Maud(atoms, logfile=None) as opt:
            opt.attach(lambda: opt.nsteps == 3 and atoms.calc.set(Q=3.0))
            converged = opt.run(fmax=1e-6)
        fresh = atoms.copy()
        fresh.calc = MaudCalculator(**atoms.calc.parameters)
        return converged and np.linalg.norm(fresh.get_forces(), axis=1).max() < 1e-6
    return [(lambda s=s, c=c: c(s)) for c in (moved, changed, observer) for s in range(4)]


def other_scenes(directory: Path):
    """A restart file or trajectory of another scene with as many points."""
    def case(seed, what):
        folder = directory / f'other{seed}{what}'
        folder.mkdir()
        files = {'restart': folder / 'maud.json', 'trajectory': folder / 'maud.traj'}
        with Maud(build('ring', 25, seed=seed), logfile=None, **files) as opt:
            opt.run(fmax=1e-6, steps=3)
        net = build('hanging_net', 5, seed=seed)
        if what == 'restart':
            Maud(net, logfile=None, restart=files['restart'])
        else:
            Maud.resume(net, logfile=None, **files)
        return False   # accepted: the defect
    return [(lambda s=s, w=w: case(s, w)) for s in range(3) for w in ('restart', 'trajectory')]


def damaged_restarts(directory: Path):
    """Hand-damaged restart values (the tests' table): refused by name, the
    atoms untouched."""
    def case(damage, seed):
        edit, _ = DAMAGES[damage]
        restart = directory / f'damaged{seed}{abs(hash(damage))}.json'
        with Maud(build('hanging_net', 8, seed=seed), logfile=None, restart=restart,
                  model='springs') as opt:
            opt.run(fmax=1e-9, steps=4)
        document = json.loads(restart.read_text())
        edit(document)
        restart.write_text(json.dumps(document))
        atoms = build('hanging_net', 8, seed=seed)
        start = atoms.positions.copy()
        try:
            Maud(atoms, logfile=None, restart=restart)
        finally:
            assert np.array_equal(atoms.positions, start)
        return False
    return [(lambda d=d, s=s: case(d, s)) for d in sorted(DAMAGES) for s in range(2)]


def cut_trajectories(directory: Path):
    """A trajectory cut short by a seeded number of bytes: resumed from its
    last intact frame to the minimum (or refused by name if cut into its
    header)."""
    def case(seed):
        folder = directory / f'cut{seed}'
        folder.mkdir()
        files = {'restart': folder / 'maud.json', 'trajectory': folder / 'maud.traj'}
        with Maud(build('hanging_net', 8, seed=seed), logfile=None, **files) as opt:
            opt.run(fmax=1e-9, steps=6)
        data = files['trajectory'].read_bytes()
        cut = int(np.random.default_rng(seed).integers(1, len(data) // 2))
        files['trajectory'].write_bytes(data[:-cut])
        with Maud.resume(build('hanging_net', 8, seed=seed), logfile=None, **files) as opt:
            converged = opt.run(fmax=1e-6)
        return converged and same_minimum(opt.optimizable.atoms, rtol=1e-7)
    return [(lambda s=s: case(s)) for s in range(8)]


def second_writers(directory: Path):
    """A second run on the restart file or trajectory of a running one."""
    def case(seed, which):
        folder = directory / f'writer{seed}{which}'
        folder.mkdir()
        files = {'restart': folder / 'maud.json', 'trajectory': folder / 'maud.traj'}
        running = Maud(build('hanging_net', 8, seed=seed), logfile=None, **files)
        steps = running.irun(fmax=1e-9, steps=30)
        next(steps), next(steps)
        try:
            Maud(build('hanging_net', 8, seed=seed), logfile=None, **{which: files[which]})
        finally:
            steps.close()
            running.close()
        return False
    return [(lambda s=s, w=w: case(s, w)) for s in range(3) for w in ('restart', 'trajectory')]


def runs_that_cannot_end():
    """A ring flattened to 1e8 x 1e-8 (a creep), a free net under a load (a
    drift): stopped with a MaudError."""
    def creep(seed):
        atoms = build('ring', 20, seed=seed)
        atoms.positions *= [1e8, 1e-8, 1.0]
        with Maud(atoms, logfile=None, patience=300) as opt:
            return opt.run(fmax=1e-3, steps=5000) and same_minimum(atoms)

    def drift(seed):
        atoms = build('hanging_net', 5, seed=seed)
        atoms.set_constraint()
        atoms.calc.set(loads=np.tile([0.0, 0.0, -0.5 - seed], (len(atoms), 1)))
        with Maud(atoms, logfile=None) as opt:
            return opt.run(fmax=1e-3, steps=20000) and False
    return [(lambda s=s: creep(s)) for s in range(3)] + [(lambda s=s: drift(s))
                                                          for s in range(3)]


def hostile_files(directory: Path):
    """The tests' malformed net files (non-UTF-8, duplicate keys, non-finite
    coordinates, huge integers, deep nesting, overlong lines, ...), a
    directory, and spring indices out of range: a ValueError naming them."""
    def case(name, text):
        path = directory / f'hostile{abs(hash(text))}{Path(name).suffix}'
        path.write_text(text)
        read_net(path)
        return False

    def springs(value):
        MaudCalculator(springs=[[0, 1], [1, value]])
        return False
    return ([(lambda n=n, t=t: case(n, t)) for n, t, _ in BROKEN]
            + [lambda: read_net(directory) and False]
            + [(lambda v=v: springs(v)) for v in (1 + 2j, 1e20, -1, 2.5, 'x', np.nan)])


def command_line(directory: Path):
    """Bad arguments of the command: exit status 2 with one line."""
    argvs = [['bench', '--fmax', '-1'], ['bench', '--fmax', '0'],
             ['bench', '--energy-rtol', 'nan'], ['backends', '--natoms', '-5'],
             ['classify', 'x.traj', '-k', '-3'], ['relax', '--out', str(directory)],
             ['relax', 'absent.obj'], ['relax', '--fix', 'nothing-such'],
             ['relax', '--scene', 'ring', '--load', '0', 'x', '0']]

    return [(lambda a=a: refused(a)) for a in argvs]


def status_line(argv):
    """``ase-maud argv``'s exit status and what it wrote on stderr."""
    error = io.StringIO()
    with contextlib.redirect_stderr(error), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main_cli([str(a) for a in argv])
        except SystemExit as stop:   # argparse's own errors
            status = stop.code
    return status, error.getvalue()


def refused(argv):
    """A ValueError of ``ase-maud argv``'s one-line error if it exits with
    status 2 and one line; else False (a defect)."""
    status, error = status_line(argv)
    if status == 2 and error.count('\n') == 1:
        raise ValueError(error.strip())
    return False


def outputs_over_inputs(directory: Path):
    """Outputs that name an input or another output (the command line and
    Maud's files), and a run refused before its first step: a one-line
    ValueError, every file byte for byte as it was."""
    def case(argv, *kept, seed=0):
        folder = directory / f'clash{abs(hash(str(argv)))}'
        folder.mkdir(exist_ok=True)
        net = folder / 'net.obj'
        write_net(net, build('hanging_net', 4, seed=seed))
        (folder / 'fixed.txt').write_text('0\n3\n')
        write_net(folder / 'p.xyz', build('ring', 6, seed=seed))
        write_net(folder / 'net.json', build('hanging_net', 4, seed=seed))   # the user's
        before = {name: (folder / name).read_bytes() for name in kept}
        with contextlib.chdir(folder):
            status, error = status_line(argv)
        if any((folder / name).read_bytes() != data for name, data in before.items()):
            return False   # data lost
        if status == 2 and error.count('\n') == 1:
            raise ValueError(error.strip())
        return False   # a raw error, or written over

    def previous_trajectory_kept():
        folder = directory / 'previous'
        folder.mkdir(exist_ok=True)
        with contextlib.chdir(folder):
            status_line(['relax', '--scene', 'ring', '--size', '6', '--quiet'])
            before = Path('maud.traj').read_bytes()
            write_net('free.obj', build('net3d', 3, seed=2))   # nothing fixed: it drifts
            status, _ = status_line(['relax', 'free.obj', '--load', '0', '0', '-1', '--quiet'])
            return status == 2 and Path('maud.traj').read_bytes() == before

    def maud_files(files):
        with contextlib.suppress(FileNotFoundError):
            for name in files.values():
                (directory / name).unlink()
        with contextlib.chdir(directory):
            Maud(build('ring', 6), **files)
        return False
    argvs = [(['relax', 'net.obj', '--fix', 'fixed.txt', '--traj', 'net.obj'], 'net.obj'),
             (['relax', 'net.obj', '--fix', 'fixed.txt', '--log', 'fixed.txt'], 'fixed.txt'),
             (['relax', 'p.xyz', '--traj', 'p.edges.txt'], 'p.edges.txt', 'p.xyz'),
             (['relax', 'p.xyz', '--edges', 'p.edges.txt', '--log', './p.edges.txt'],
              'p.edges.txt'),
             (['relax', 'p.xyz', '--out', 'p.extxyz'], 'p.edges.txt'),
             (['relax', 'net.obj', '--fix', 'fixed.txt', '--out', 'net.obj'], 'net.obj'),
             (['relax', 'net.obj', '--fix', 'fixed.txt', '--traj', 'r.obj', '--out', 'r.obj'],
              'net.obj'),
             (['relax', '--scene', 'ring', '--out', 'maud.traj'],),
             (['show', 'net.obj', '--fix', 'fixed.txt', '-o', 'net.obj'], 'net.obj'),
             (['saddles', 'p.xyz', '--out', 'net.png', '--edges', 'p.edges.txt'],
              'net.json')]
    files = [dict(restart='m.json', logfile='m.json'), dict(restart='m.json',
             trajectory='./m.json'), dict(logfile='m.traj', trajectory='m.traj'),
             dict(restart='m.json', trajectory='m.json.arrays')]
    return ([(lambda a=a: case(*a)) for a in argvs] + [previous_trajectory_kept]
            + [(lambda f=f: maud_files(f)) for f in files])


def arguments_where_they_enter(directory: Path):
    """Frames past the end, landscape's tolerances, an edge listed both ways
    with two q, write_net without a MaudCalculator, an XYZ declaring more
    atoms than it holds, a continued OBJ vertex, a 400-digit coordinate,
    ragged springs, a repeated fixed point, loads beyond float64: a
    ValueError naming them."""
    from ase.io.trajectory import Trajectory

    from ase_maud.saddles.landscape import landscape
    traj = directory / 'four.traj'
    atoms = build('ring', 6, seed=3)
    atoms.get_potential_energy()
    with Trajectory(traj, 'w') as frames:
        for _ in range(4):
            frames.write(atoms)

    def text(name, content):
        path = directory / name
        path.write_text(content)
        return path

    def graph(q, r):
        node = {str(n): {'x': float(n), 'y': 0.0, 'z': 0.0, 'is_anchor': n != 1}
                for n in range(3)}
        return json.dumps({'dtype': 'compas.datastructures/Graph', 'data': {
            'node': node, 'edge': {'0': {'1': {'q': q}}, '1': {'0': {'q': r}, '2': {}}}}})
    huge = graph(1, 1).replace('"x": 1.0', '"x": 1' + '0' * 400)
    def loads_beyond_float64():
        atoms = build('ring', 8, seed=4)
        atoms.calc.set(loads=np.full((8, 3), 1e308) * [1, 1, 0])
        atoms.get_potential_energy()

    def with_emt(atoms):
        atoms.calc = EMT()
        return atoms
    cases = [lambda: read_net(traj, index=-999), lambda: read_net(traj, index=4),
             lambda: refused(['classify', traj, '--frame', '5']),
             lambda: read_net(text('one.obj', 'v 0 0 0\nv 1 0 0\nl 1 2\n'), index=5)]
    minimum = build('ring', 6, seed=5)
    Maud(minimum, logfile=None).run(fmax=1e-7)
    cases += [(lambda k=k, v=v: landscape(minimum, fmax=1e-6, **{k: v}))
              for k, v in (('energy_rtol', -1), ('distance_atol', np.nan), ('modes', -1),
                           ('modes', 2.5))]
    cases += [lambda: read_net(text('both.json', graph(2, 5))),
              lambda: write_net(directory / 'bare.obj', build('ring', 5)[:3]),
              lambda: write_net(directory / 'emt.obj', with_emt(Icosahedron('Cu', 2))),
              lambda: read_net(text('big.xyz', '100000000\n\nH 0 0 0\nH 1 0 0\n')),
              lambda: read_net(text('later.xyz', '2\n\nH 0 0 0\nH 1 0 0\n10000000\n\n')),
              lambda: read_net(text('cont.obj', 'v 0 0 0\nv 1 0 \\\n0\nl 1 2\n')),
              lambda: read_net(text('huge.json', huge)),
              lambda: MaudCalculator(springs=[[0, 1], [1, 2, 3]]),
              lambda: read_net(text('twice.obj', 'v 0 0 0\nv 1 0 0\nv 2 0 0\nl 1 2 3\n'),
                               fixed=text('twice.txt', '0 2\n2\n')),
              loads_beyond_float64]
    return [(lambda c=c: c() and False) for c in cases]


def misspelt_keywords():
    """Calculator keywords that do not exist, in the constructor and set()."""
    def case(name, where):
        if where == 'constructor':
            MaudCalculator(springs=[[0, 1]], **{name: 3})
        else:
            MaudCalculator(springs=[[0, 1]]).set(**{name: 3})
        return False
    return [(lambda n=n, w=w: case(n, w)) for n in ('qq', 'spring', 'A', 'load')
            for w in ('constructor', 'set')]


def leftovers(directory: Path):
    """Temporary files of writers killed before their replace: removed by the
    next run if older than a minute, a live one kept."""
    def case(seed):
        folder = directory / f'left{seed}'
        folder.mkdir()
        restart = folder / 'maud.json'
        with Maud(build('hanging_net', 5, seed=seed), logfile=None, restart=restart) as opt:
            opt.run(fmax=1e-9, steps=2)
        old, live = folder / '.maud.k1ll3d.tmp.json', folder / '.maud.l1ve.tmp.json'
        old.write_text('{"half')
        live.write_text('{"half')
        past = time.time() - 2 * LEFTOVER_SECONDS
        os.utime(old, (past, past))
        with Maud(build('hanging_net', 5, seed=seed), logfile=None, restart=restart) as opt:
            opt.run(fmax=1e-9, steps=2)
        return not old.exists() and live.exists()
    return [(lambda s=s: case(s)) for s in range(3)]


def ase_filters():
    """ASE's Filter (a subset) with every stiffness model, and its cell
    filters on a periodic crystal (EMT), against BFGS on the same filter."""
    def subset(model, seed):
        atoms = build('hanging_net', 6, seed=seed)
        supports = set(atoms.constraints[0].index.tolist())
        atoms.set_constraint()
        free = [i for i in range(len(atoms)) if i not in supports]
        with Maud(Filter(atoms, indices=free), logfile=None, model=model) as opt:
            converged = opt.run(fmax=1e-7, steps=3000)
        held = atoms.copy()
        held.calc = MaudCalculator(**atoms.calc.parameters)
        held.set_constraint(FixAtoms(indices=sorted(supports)))
        return converged and same_minimum(held)

    def cell(kind, seed):
        converged, energy, expected = relaxed_in_a_cell_filter(kind, seed)
        return converged and abs(energy - expected) < 1e-6
    models = ('auto', 'exact', 'springs', 'nodal', 'global', 'secant')
    return ([(lambda m=m, s=s: subset(m, s)) for m in models for s in range(2)]
            + [(lambda k=k, s=s: cell(k, s)) for k in (UnitCellFilter, FrechetCellFilter,
                                                       StrainFilter) for s in range(2)])


def constraints():
    """ASE constraints beyond FixAtoms/FixCartesian on a Maud net: the run
    ends where BFGS ends under the same constraints, or in another minimum
    (BFGS from a point beside it comes back to it)."""
    def constrained_bfgs(atoms, rattle=0.0, seed=0):
        copy = atoms.copy()
        copy.calc = MaudCalculator(**atoms.calc.parameters)
        copy.set_constraint([c.copy() for c in atoms.constraints])
        copy.rattle(rattle, seed=seed)
        BFGS(copy, logfile=None).run(fmax=1e-8, steps=5000)
        return copy.get_potential_energy()

    def case(make, seed):
        atoms = build('hanging_net', 5, seed=seed)
        atoms.set_constraint([*atoms.constraints, make(atoms)])
        expected = constrained_bfgs(atoms)
        with Maud(atoms, logfile=None) as opt:
            converged = opt.run(fmax=1e-7, steps=5000)
        energy = atoms.get_potential_energy()
        return converged and (abs(energy - expected) < 1e-9 * abs(expected) or abs(
            constrained_bfgs(atoms, 1e-3, seed) - energy) < 1e-9 * abs(energy))
    makes = [lambda a: FixedPlane(12, [0, 0, 1]), lambda a: FixedLine(12, [1, 0, 0]),
             lambda a: Hookean(6, 18, 1.0, 1.0), lambda a: FixBondLength(6, 7)]
    return [(lambda m=m, s=s: case(m, s)) for m in makes for s in range(2)]


def threads_sharing_a_calculator():
    """Threads, each with its own atoms, sharing one MaudCalculator: each
    gets its own atoms' energy and forces (the tests' measure)."""
    return [(lambda s=s: wrong_results_of_threads(s, threads=8, calls=50) == 0)
            for s in range(4)]


def long_runs(directory: Path):
    """Runs of 20000 steps or more (fmax below the forces' rounding): they end
    (converged or stagnant), and the restart file stays the size of its
    slots, not of the run."""
    def case(name, size, seed):
        restart = directory / f'long{name}{seed}.json'
        atoms = build(name, size, seed=seed)
        rows = 3 * len(atoms)
        try:
            with Maud(atoms, logfile=None, restart=restart, patience=20000) as opt:
                opt.run(fmax=1e-16, steps=20000)
        except MaudError:
            pass
        arrays = restart.with_name(restart.name + '.arrays').stat().st_size
        memory = opt.strategy.rule.memory
        return arrays <= (6 + 2 * (memory + 1)) * rows * 8 and np.isfinite(
            atoms.positions).all() and opt.nsteps <= 20000
    return [(lambda n=n, z=z, s=s: case(n, z, s))
            for n, z in (('chain', 30), ('hanging_net', 12)) for s in range(2)]


# -- issue 52: outputs where the user pointed, inputs read or refused, ASE's --
# -- convergence cases, the last raw tracebacks --------------------------------

class DataLost(Exception):
    """A file of the user's (a device, a pipe, a link's target) replaced or lost."""


class Hang(Exception):
    """A run that did not end within its (generous) time."""


#: What each issue-52 case is judged as (module docstring of the classes below).
KINDS = ('correct', 'clear error', 'data lost', 'silently wrong', 'hang', 'false error',
         'raw traceback')


def judged(expect: str, run) -> str:
    """The kind (:data:`KINDS`) of ``run()``, which returns True for a right
    answer (False: a wrong one) and raises DataLost or Hang: ``expect`` is
    'ok' (a valid input: an error is a false error) or 'refuse' (an answer
    is silently wrong, a ValueError or MaudError a clear error)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            right = run()
    except DataLost:
        return 'data lost'
    except Hang:
        return 'hang'
    except (ValueError, MaudError, OSError) as error:
        clear = bool(str(error)) and type(error).__name__ in (
            'ValueError', 'OSError') or isinstance(error, MaudError)
        if not clear:
            return 'raw traceback'
        return 'clear error' if expect == 'refuse' else 'false error'
    except (Exception, SystemExit):   # noqa: BLE001 (counted; a library's exit too)
        return 'raw traceback'
    if expect == 'refuse' or not right:
        return 'silently wrong'
    return 'correct'


def cli(folder: Path, *argv: str, timeout: float = 300.0) -> tuple[int, str]:
    """``python -m ase_maud argv`` in ``folder`` (a subprocess: a hang is
    caught by ``timeout``, generous for a busy machine): status, stderr."""
    import subprocess
    try:
        run = subprocess.run([sys.executable, '-m', 'ase_maud', *argv], cwd=folder,
                             capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise Hang(' '.join(argv)) from None
    return run.returncode, run.stderr


def refused_or(status: int, error: str, done: bool) -> bool:
    """True for a run that did what was asked (``done``) with status 0; a
    ValueError for a one-line refusal (status 2); else a raw traceback."""
    if status == 2 and error.strip().count('\n') == 0 and error.startswith('ase-maud'):
        raise ValueError(error.strip())
    if status not in (0, 2):
        raise RuntimeError(error.strip()[-300:])
    return status == 0 and done


def special_outputs(directory: Path):
    """Every writer's output as a device node (a twin of /dev/null made in a
    temporary folder; root only), a named pipe nobody reads, a link, a link
    to nothing, a name ending in '/', a 250-byte name: ('ok' or 'refuse', run)."""
    import stat as stat_module
    relax = ['relax', '--scene', 'ring', '--size', '6', '--quiet']
    options = {'--forces': ('.csv', relax), '--traj': ('.traj', relax),
               '--out json': ('.json', relax), '--out obj': ('.obj', relax),
               '--out xyz': ('.xyz', relax), '--log': ('.log', relax)}
    cases = []

    def folder_for(name):
        folder = directory / f'special{len(list(directory.glob("special*")))}{name}'
        folder.mkdir()
        return folder

    def device(option, suffix, argv):
        if os.geteuid() != 0:
            return True   # no device node without root: nothing to judge
        folder = folder_for('dev')
        os.mknod(folder / 'null', 0o666 | stat_module.S_IFCHR, os.makedev(1, 3))
        os.symlink('null', folder / f'null{suffix}')   # a net's format is its suffix
        status, error = cli(folder, *argv, option.split()[0], f'null{suffix}')
        if not stat_module.S_ISCHR(os.stat(folder / 'null').st_mode):
            raise DataLost(option)
        return refused_or(status, error, True)

    def pipe(option, suffix, argv):
        folder = folder_for('fifo')
        os.mkfifo(folder / f'pipe{suffix}')
        status, error = cli(folder, *argv, option.split()[0], f'pipe{suffix}', timeout=600)
        if not stat_module.S_ISFIFO(os.stat(folder / f'pipe{suffix}').st_mode):
            raise DataLost(option)
        return refused_or(status, error, False)   # nothing reads it: refused

    def link(option, suffix, argv, dangling):
        folder = folder_for('link')
        target = folder / f'real{suffix}'
        if not dangling:
            target.write_text('old\n')
        os.symlink(target.name, folder / f'link{suffix}')
        status, error = cli(folder, *argv, option.split()[0], f'link{suffix}')
        if not (folder / f'link{suffix}').is_symlink():
            raise DataLost(option)
        done = target.exists() and target.read_bytes() != b'old\n'
        return refused_or(status, error, done)

    def slash(option, suffix, argv):
        folder = folder_for('slash')
        (folder / 'outdir').mkdir()
        status, error = cli(folder, *argv, option.split()[0], 'outdir/')
        if [p.name for p in folder.iterdir()] != ['outdir'] or any(
                (folder / 'outdir').iterdir()):
            return False   # misplaced
        return refused_or(status, error, False)

    def long_name(option, suffix, argv):
        folder = folder_for('long')
        name = 'n' * (250 - len(suffix)) + suffix
        status, error = cli(folder, *argv, option.split()[0], name)
        return refused_or(status, error, (folder / name).exists())
    for option, (suffix, argv) in options.items():
        cases += [('ok', lambda o=option, s=suffix, a=argv: device(o, s, a)),
                  ('refuse', lambda o=option, s=suffix, a=argv: pipe(o, s, a)),
                  ('ok', lambda o=option, s=suffix, a=argv: link(o, s, a, False)),
                  ('ok', lambda o=option, s=suffix, a=argv: link(o, s, a, True)),
                  ('refuse', lambda o=option, s=suffix, a=argv: slash(o, s, a)),
                  # an XYZ's edge list beside it (NAME.edges.txt) is over 255 bytes:
                  # refused before any work
                  ('refuse' if suffix == '.xyz' else 'ok',
                   lambda o=option, s=suffix, a=argv: long_name(o, s, a))]

    def show(kind):
        folder = folder_for('show')
        write_net(folder / 'net.obj', build('ring', 6, seed=1))
        if kind == 'link':
            os.symlink('real.png', folder / 'link.png')
            status, error = cli(folder, 'show', 'net.obj', '-o', 'link.png')
            if not (folder / 'link.png').is_symlink():
                raise DataLost('show -o')
            return refused_or(status, error, (folder / 'real.png').exists())
        os.mkfifo(folder / 'pipe.png')
        status, error = cli(folder, 'show', 'net.obj', '-o', 'pipe.png', timeout=600)
        return refused_or(status, error, False)
    cases += [('ok', lambda: show('link')), ('refuse', lambda: show('pipe'))]
    return cases


PLY_TEXT = ('ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n'
            'property float z\nelement face {n}\nproperty list uchar int vertex_indices\n'
            'end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n{rows}')


def mesh_inputs(directory: Path):
    """Mesh files: face indices out of range, faces twice, what meshio
    cannot read, OFF of any face size: ('ok' or 'refuse', run)."""
    def text(name, content):
        path = directory / f'in52{abs(hash(content))}{name}'
        path.write_text(content)
        return path

    def ply(*faces):
        return text('.ply', PLY_TEXT.format(n=len(faces), rows=''.join(
            f'{len(f)} {" ".join(map(str, f))}\n' for f in faces)))

    def square(path, **keywords):
        atoms = read_net(path, **keywords)
        edges = sorted(map(tuple, atoms.calc.springs.tolist()))
        return edges == [(0, 1), (0, 3), (1, 2), (2, 3)] or edges == [
            (0, 1), (0, 2), (0, 3), (1, 2), (2, 3)]

    def boundary(path):
        atoms = read_net(path, fixed='boundary')
        return sorted(atoms.constraints[0].index.tolist()) == [0, 1, 2, 3]
    refuse = [lambda v=v: read_net(ply((0, 1, 2), (0, 2, v))) and False
              for v in (-1, -4, 4, 1000)]
    refuse += [lambda: read_net(text('.stl', 'solid x\nendsolid x\n')) and False,
               lambda: read_net(text('.stl', '')) and False,
               lambda: read_net(text('.vtk', '# vtk DataFile Version 4.2\nx\nASCII\nDATASET '
                                     'UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0'
                                     '\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n4\n')) and False,
               lambda: read_net(text('.off', 'OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 5\n'))
               and False]
    ok = [lambda: square(text('.off', 'OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n')),
          lambda: square(text('.off', 'OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n'
                              '4 0 1 2 3 255 0 0\n')),
          lambda: square(text('.off', 'NOFF\n4 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n'
                              '0 1 0 0 0 1\n4 0 1 2 3\n')),
          lambda: boundary(ply((0, 1, 2), (0, 2, 3), (2, 1, 0))),
          lambda: boundary(text('.obj', 'v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\n'
                                'f 1 3 4\nf 3 2 1\n'))]
    return [('refuse', r) for r in refuse] + [('ok', o) for o in ok]


def round_trips(directory: Path):
    """Each writer's file read back, with and without the options that wrote
    it, is the scene written (forces equal): ('ok', run)."""
    from ase_maud.bench.hard_inputs import round_trip_scene as scene  # shared with the tests

    def case(kind, seed, given):
        atoms = scene(seed)
        path = directory / f'trip{kind}{seed}{given}.{kind}'
        write_net(path, atoms)
        p = atoms.calc.parameters
        options = {'a': p['a'], 'Q': p['Q']} if given or kind in ('obj', 'xyz') else {}
        if kind in ('obj', 'xyz'):
            options.update(fixed=atoms.constraints[0].index.tolist(), dim=3)
        back = read_net(path, **options)
        if kind in ('obj', 'xyz'):
            back.calc.set(q=p['q'], loads=p['loads'])   # OBJ and XYZ hold neither
        return np.allclose(back.get_forces(), atoms.get_forces(), rtol=1e-12, atol=1e-12)

    def relaxed(seed):
        folder = directory / f'tripcli{seed}'
        folder.mkdir()
        write_net(folder / 'net.obj', build('hanging_net', 5, seed=seed))
        (folder / 'fixed.txt').write_text('\n'.join(map(str, build(
            'hanging_net', 5, seed=seed).constraints[0].index.tolist())) + '\n')
        status, error = cli(folder, 'relax', 'net.obj', '--fix', 'fixed.txt', '--Q', '2',
                            '--a', '0.5', '--fmax', '1e-6', '--quiet', '--out', 'r.json')
        refused_or(status, error, True)
        return all(np.linalg.norm(read_net(folder / 'r.json', **given).get_forces(),
                                  axis=1).max() < 1e-6 for given in ({}, {'Q': 2.0, 'a': 0.5}))
    return ([('ok', lambda k=k, s=s, g=g: case(k, s, g)) for k in ('json', 'traj', 'obj', 'xyz')
             for s in range(2) for g in (False, True)]
            + [('ok', lambda s=s: relaxed(s)) for s in range(2)])


def arguments_as_written(directory: Path):
    """--load in scientific notation, a flat mesh under out-of-plane --loads
    (3D unless --dim 2 is given), the documented canopy example."""
    import meshio

    def canopy(folder):
        n = 6
        x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
        quads = [[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j]
                 for i in range(n - 1) for j in range(n - 1)]
        meshio.write(folder / 'canopy.ply', meshio.Mesh(
            np.c_[x.ravel(), y.ravel(), np.zeros(n * n)], [('quad', np.array(quads, np.int32))]),
            binary=False)
        (folder / 'loads.csv').write_text('i,px,py,pz\n' + ''.join(
            f'{k},0,0,-0.2\n' for k in range(n * n)))

    def case(*argv, expect_dim=None):
        folder = directory / f'args{abs(hash(argv))}'
        folder.mkdir()
        canopy(folder)
        status, error = cli(folder, 'relax', 'canopy.ply', '--fix', 'outer', '--quiet',
                            '--out', 'out.json', *argv)
        refused_or(status, error, True)
        return read_net(folder / 'out.json').calc.dim == expect_dim
    ok = [lambda z=z: case('--load', '0', '0', z, expect_dim=3)
          for z in ('-1e-3', '-1E-3', '-.5e-2', '-0.001', '-1e+0')]
    ok += [lambda: case('--loads', 'loads.csv', '--forces', 'forces.csv', expect_dim=3)]
    refuse = [lambda: case('--loads', 'loads.csv', '--dim', '2', expect_dim=2),
              lambda: case('--load', '0', '0', '-1e-3x')]
    return [('ok', o) for o in ok] + [('refuse', r) for r in refuse]


def ase_converges(directory: Path):
    """Where BFGS converges: undeclared energy noise, a = 0 nets with force
    densities spread over decades, a ring of 8 with a point held (saddle),
    BasinHopping of LJ6 with dr=2.5 (bounded force calls)."""
    from ase import Atoms
    from ase.calculators.lj import LennardJones

    from ase_maud.bench.doubles import UndeclaredNoise

    def both(make, fmax, steps=1000, **keywords):
        ends = []
        for optimizer in (BFGS, Maud):
            atoms = make()
            with optimizer(atoms, logfile=None, **(keywords if optimizer is Maud else {})) \
                    as opt:
                ends.append((opt.run(fmax=fmax, steps=steps), atoms))
        return ends

    def noisy(scene, size, seed):
        def make():
            atoms = build(scene, size, seed=seed)
            atoms.calc = UndeclaredNoise(MaudCalculator(**atoms.calc.parameters), 1e-2, seed)
            return atoms
        (bfgs, _), (maud, atoms) = both(make, 1e-4)
        exact = atoms.copy()
        exact.calc = MaudCalculator(**{**atoms.calc.inner.parameters, 'backend': 'numpy'})
        return bfgs and maud and np.linalg.norm(exact.get_forces(), axis=1).max() < 1e-4

    def linear(size, spread, seed):
        q = np.exp(np.random.default_rng(seed).uniform(-1, 1, 2 * size * (size - 1))
                   * np.log(spread))

        def make():
            atoms = build('hanging_net', size, seed=seed)
            atoms.calc.set(a=0.0, q=q[:len(atoms.calc.springs)],
                           loads=np.tile([0.0, 0.0, -0.1], (len(atoms), 1)))
            return atoms
        (bfgs, reference), (maud, atoms) = both(make, 1e-6, 3000)
        return bfgs and maud and np.allclose(atoms.positions, reference.positions,
                                             atol=1e-4 * np.abs(reference.positions).max())

    def held_ring(seed):
        atoms = build('ring', 8, seed=seed)
        atoms.set_constraint([*atoms.constraints, FixAtoms(indices=[0])])
        with Maud(atoms, logfile=None, target='saddle') as opt:
            return opt.run(fmax=1e-6, steps=1000) and opt.found.verdict == 'saddle'

    def hops(seed):
        calls = []
        for optimizer in (BFGS, Maud):
            half = 6 ** (1 / 3)
            atoms = Atoms('He6', positions=np.random.RandomState(42 + seed).uniform(
                -half, half, (6, 3)))
            atoms.calc = LennardJones()
            count, calculate = [0], atoms.calc.calculate

            def counted(*args, count=count, calculate=calculate, **kwargs):
                count[0] += 1
                if count[0] > 100000:
                    raise Hang('basin hopping: over 100000 force calls')
                return calculate(*args, **kwargs)
            atoms.calc.calculate = counted
            np.random.seed(seed)
            with BasinHopping(atoms, temperature=1.0, dr=2.5, optimizer=optimizer,
                              logfile=None, optimizer_logfile=None, trajectory=None,
                              local_minima_trajectory=None) as hopping:
                hopping.run(10)
            calls.append(count[0])
        return calls[1] <= 5 * calls[0]
    return ([('ok', lambda c=c, z=z, s=s: noisy(c, z, s)) for c, z in
             (('hanging_net', 5), ('random_graph', 12), ('hanging_net', 10)) for s in range(2)]
            + [('ok', lambda z=z, p=p, s=s: linear(z, p, s)) for z in (5, 7, 10)
               for p in (1e1, 1e3, 1e6) for s in range(2)]
            + [('ok', lambda s=s: held_ring(s)) for s in range(3)]
            + [('ok', lambda s=s: hops(s)) for s in range(3)])


def last_tracebacks(directory: Path):
    """The raw tracebacks issue 52 lists: each a clear error now ('refuse')."""
    from ase.calculators.calculator import Calculator, all_changes

    from ase_maud import search_saddles

    class Reduced(Calculator):
        implemented_properties = ['energy', 'forces']

        def __init__(self, flat):
            super().__init__()
            self.flat = flat
            if not flat:
                self.implemented_properties = ['forces']

        def calculate(self, atoms=None, properties=('energy',), system_changes=all_changes):
            super().calculate(atoms, properties, system_changes)
            forces = -atoms.positions.copy()
            self.results = {'forces': forces[:, :2]} if self.flat else {'forces': forces}
            if self.flat:
                self.results['energy'] = 0.0

    def copper(calc):
        atoms = Icosahedron('Cu', 2)
        atoms.rattle(0.05, seed=1)
        atoms.calc = calc
        return atoms

    def minimum():
        atoms = build('ring', 8, seed=1)
        Maud(atoms, logfile=None).run(fmax=1e-6)
        return atoms

    def disc():
        status, error = cli(directory, 'relax', '--scene', 'disc', '--size', '10', '--quiet')
        return refused_or(status, error, False)
    cases = [lambda m=m: Maud(copper(EMT()), logfile=None, model=m).run(fmax=1e-3, steps=20)
             for m in ('springs', 'near')]
    cases += [lambda f=f: Maud(copper(Reduced(f)), logfile=None).run(fmax=1e-3, steps=20)
              for f in (True, False)]
    cases += [lambda: Maud(UnitCellFilter(build('hanging_net', 5, seed=1)),
                           logfile=None).run(fmax=1e-3, steps=20),
              disc, lambda: search_saddles(minimum(), client=object())]
    return [('refuse', lambda c=c: c() and False) for c in cases]


def issue_52_classes(directory: Path):
    return [('special files, links, names as outputs (each writer)',
             special_outputs(directory)),
            ('mesh inputs: face indices, faces twice, meshio failures, OFF',
             mesh_inputs(directory)),
            ("round trips of every writer under the options that wrote it",
             round_trips(directory)),
            ('arguments as written: --load 0 0 -1e-3, flat nets under --loads',
             arguments_as_written(directory)),
            ("where BFGS converges: noise, a = 0 spreads, a held ring's saddle, hops",
             ase_converges(directory)),
            ('the raw tracebacks listed', last_tracebacks(directory))]


def main_52() -> None:
    """The issue-52 classes alone: per class, each kind of :data:`KINDS`."""
    with tempfile.TemporaryDirectory() as name:
        directory = Path(name)
        print('| class | inputs | ' + ' | '.join(KINDS) + ' |')
        print('| --- ' * (len(KINDS) + 2) + '|')
        total, defects = Counter(), []
        for title, cases in issue_52_classes(directory):
            counts = Counter()
            for expect, run in cases:
                kind = judged(expect, run)
                counts[kind] += 1
                if kind not in ('correct', 'clear error'):
                    defects.append(f'{title}: {kind} (case {sum(counts.values())})')
            total += counts
            print(f'| {title} | {len(cases)} | '
                  + ' | '.join(str(counts[k]) for k in KINDS) + ' |', flush=True)
        print(f'| all | {sum(total.values())} | '
              + ' | '.join(str(total[k]) for k in KINDS) + ' |')
    for line in defects:
        print(' -', line, file=sys.stderr)


def main() -> None:
    if '--issue-52' in sys.argv:
        main_52()
        return
    with tempfile.TemporaryDirectory() as name:
        directory = Path(name)
        classes = [('unchecked run arguments (fmax x steps)', run_arguments()),
                   ('keywords (each x hostile values)', keywords()),
                   ('file arguments', files(directory)),
                   ('stale results at small scales', small_scales()),
                   ('NaN reaching the user', non_finite(directory)),
                   ('overflow at extreme scales (H2)', extreme_scales()),
                   ('FMM near pairs (H2)', fmm_near_pairs()),
                   ('2D scenes under ASE drivers', planar_drivers()),
                   ('unclear errors (builders, calculator)', unclear_errors()),
                   ("the user's files: write-back over the input, a full disk",
                    users_files(directory)),
                   ('second runs: atoms moved, calc.set between runs and by an observer',
                    second_runs()),
                   ('restart files and trajectories of another scene',
                    other_scenes(directory)),
                   ('hand-damaged restart files', damaged_restarts(directory)),
                   ('trajectories cut short', cut_trajectories(directory)),
                   ('a second writer on a running run\'s files', second_writers(directory)),
                   ('runs that cannot end: a creep, a drift', runs_that_cannot_end()),
                   ('malformed net files, spring indices', hostile_files(directory)),
                   ('command-line arguments', command_line(directory)),
                   ('outputs over inputs or each other, a run refused before its first '
                    'step', outputs_over_inputs(directory)),
                   ('arguments where they enter: frames, tolerances, sizes, q twice, ...',
                    arguments_where_they_enter(directory)),
                   ('misspelt calculator keywords', misspelt_keywords()),
                   ('temporary files of killed writers', leftovers(directory)),
                   ('ASE filters: a subset x models, cell filters', ase_filters()),
                   ('other ASE constraints', constraints()),
                   ('threads sharing one calculator', threads_sharing_a_calculator()),
                   ('runs of 20000 steps', long_runs(directory))]
        print('| class | inputs | correct answer | ValueError | MaudError | other |')
        print('| --- | --- | --- | --- | --- | --- |')
        others = []
        for title, runs in classes:
            counts = Counter()
            for run in runs:
                result = outcome(run)
                counts[result.split(':')[0]] += 1
                if result != 'correct':
                    others.append(f'{title}: {result}')
            print(f'| {title} | {len(runs)} | {counts["correct"]} | {counts["ValueError"]} '
                  f'| {counts["MaudError"]} | {counts["other"]} |', flush=True)
    for line in others:   # every error's message, and the defects
        print(' -', line[:300], file=sys.stderr)


if __name__ == '__main__':
    main()
