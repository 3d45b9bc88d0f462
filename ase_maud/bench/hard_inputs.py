"""Hard inputs shared by the tests and ``dev/hostile_sweep.py``: malformed net
files (:data:`BROKEN`), hand-damaged restart values (:data:`DAMAGES`), threads
sharing one calculator (:func:`wrong_results_of_threads`), ASE's cell
filters on an EMT crystal (:func:`relaxed_in_a_cell_filter`) and the net of
random q, loads, a and Q every writer must read back (:func:`round_trip_scene`).

Each is a case a test asserts and the sweep repeats over more seeds; they live
in the package so that both import the same cases (no script reaches into
``tests/``). Nothing else in the package uses them.
"""

import threading

import numpy as np
from ase.build import bulk
from ase.calculators.emt import EMT
from ase.optimize import BFGS

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.optimize.maud import Maud
from ase_maud.scenes.catalogue import build

#: Malformed net files: (file name, text, the message ``read_net`` raises, a regex).
BROKEN = [
    ('net.obj', 'v 0 0 0\nv 1 0\n', r'net\.obj line 2: expected .v x y z., got 2'),
    ('net.obj', 'v 0 0 0\nv 1 a 0\n', r'net\.obj line 2: expected .v x y z. with numbers'),
    ('net.obj', '# c\nv 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 12\n',
     r'net\.obj line 6: face index 12 out of range \(3 vertices\)'),
    ('net.obj', 'v 0 0 0\nv 1 0 0\nl 1 -3\n', r'net\.obj line 3: line index -3 out of range'),
    ('net.obj', 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n', r'net\.obj line 4: expected integer'),
    ('net.obj', 'v 0 0 0\nv 1 0 0\nf 1 2\n', r'net\.obj line 3: a .f. needs at least 3'),
    ('net.obj', 'v 0 0 0\nv 1 0 0\nl 0 1\n', r'net\.obj line 3: vertex index 0'),
    ('net.obj', 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n', r'net\.obj line 4: vertex 2 repeats'),
    ('net.obj', '# nothing\n', r'no vertices'),
    ('net.json', '{"vertex": {"0": {"x": 0}},\n "face": {}\n', r'net\.json line 3: not valid JSON'),
    ('net.json', '{"node": {"0": {"x": 0, "y": 0}}, "edge": {}}',
     r'net\.json: vertex 0 has no number z'),
    ('net.json', '{"node": {"0": {"x": 0, "y": 0, "z": 0}}, "edge": {"0": {"7": {}}}}',
     r"net\.json: edge 0-7 names vertex '7'"),
    ('net.json', '{"dtype": "compas.geometry/Point", "data": [0, 0, 0]}',
     r'expected COMPAS mesh data'),
    ('net.obj', 'v 0 0 0\nv nan 0 0\n', r'net\.obj line 2: coordinates must be finite'),
    ('net.obj', 'v 0 0 0\nv 1 1e400 0\n', r'net\.obj line 2: coordinates must be finite'),
    ('net.json', '{"node": {"0": {"x": NaN, "y": 0, "z": 0}}, "edge": {}}',
     r'net\.json vertex 0: coordinates must be finite'),
    ('net.json', '{"node": {"0": {"x": 0, "y": 0, "z": 0}, "0": {"x": 1, "y": 0, "z": 0}},'
     ' "edge": {}}', r"net\.json: key '0' appears twice"),
    ('net.json', '{"node": {"0": {"x": 0, "y": 0, "z": 0, "is_anchor": "false"}}, "edge": {}}',
     r"net\.json: vertex 0 has is_anchor = 'false'; expected true or false"),
    ('net.json', '{"node": {"0": [0, 0, 0]}, "edge": {}}',
     r'net\.json: vertex 0 is \[0, 0, 0\], not an object'),
    ('net.json', '{"node": {"0": {"x": 0, "y": 0, "z": 0}}, "edge": [1, 2]}',
     r'net\.json: "edge" must be an object, got list'),
    ('net.json', '{"vertex": {"0": {"x": 0, "y": 0, "z": 0}}, "face": {"0": 7}}',
     r'net\.json: "face" entry \'0\' must be a list, got 7'),
    ('net.json', '{"node": {"0": {"x": 1' + '0' * 5000 + ', "y": 0, "z": 0}}, "edge": {}}',
     r'net\.json: Exceeds the limit \(4300 digits\)'),
    ('net.json', '[' * 100000 + ']' * 100000, r'net\.json: nested too deeply'),
    ('net.obj', 'v 0 0 0\nv 1 0 0\nl 1 ' + '9' * 5000 + '\n',
     r'net\.obj line 3: expected integer vertex indices'),
    ('net.obj', 'v 0 0 ' + '1' * 1_100_000, r'net\.obj line 1: longer than 1000000 characters'),
]


def _set(key, value):
    def edit(document):
        document[key] = value
    return edit


def _monitor(key, value):
    def edit(document):
        document['monitor'][key] = value
    return edit


#: Hand-damaged restart values: name: (edit of the restart document, the message, a regex).
DAMAGES = {
    'step a string': (_set('step', 'x'), "'step' must be a whole number"),
    'gamma missing': (lambda d: d.pop('gamma'), "it has no 'gamma'"),
    'gamma negative': (_set('gamma', -0.5), "'gamma' must be a positive"),
    'gamma NaN': (_set('gamma', float('nan')), "'gamma' must be a positive"),
    'rows off by one': (lambda d: d.update(rows=d['rows'] + 1), "'rows' must be a positive"),
    'rows of fewer points': (lambda d: d.update(rows=d['rows'] - 3),
                             ': rows .* are not what it wrote'),
    'slot 2': (_set('slot', 2), "'slot' must be 0 or 1"),
    'pair -1': (_set('pairs', [-1]), "'pairs' must be"),
    'pairs and crc disagree': (lambda d: d['crc']['pairs'].append(7), '"crc" names'),
    'moving a string': (_set('moving', 'yes'), "'moving' must be true or false"),
    'merit null': (_set('merit', None), "'merit' must be a finite number"),
    'model negative': (_set('model', {'kappa': -1.0}), "'model' must be an object"),
    'only its format': (lambda d: [d.pop(k) for k in list(d) if k != 'format'],
                        "it has no 'rows'"),
    'monitor empty': (_set('monitor', {}), "the monitor's state has no 'size0'"),
    'monitor best': (_monitor('best', ['x', 0]), r"the monitor's 'best' must be \[fmax, step\]"),
    'monitor size0': (_monitor('size0', -1.0), "the monitor's 'size0' must be a positive"),
}


def wrong_results_of_threads(seed, threads=12, calls=100):
    """How many of ``threads`` x ``calls`` calls, by threads that share one
    calculator (each with its own jittered net), got other energy or forces
    than a fresh calculator gives their atoms."""
    base = build('hanging_net', 10, seed=seed)
    shared = MaudCalculator(**base.calc.parameters)
    rng = np.random.default_rng(seed)
    scenes, expected = [], []
    for _ in range(threads):
        atoms = base.copy()
        atoms.positions += rng.normal(scale=0.3, size=atoms.positions.shape)
        alone = atoms.copy()
        alone.calc = MaudCalculator(**base.calc.parameters)
        expected.append((alone.get_potential_energy(), alone.get_forces()))
        atoms.calc = shared
        scenes.append(atoms)
    wrong = []

    def work(k):
        for _ in range(calls):
            energy, forces = scenes[k].get_potential_energy(), scenes[k].get_forces()
            if energy != expected[k][0] or not np.array_equal(forces, expected[k][1]):
                wrong.append(k)

    running = [threading.Thread(target=work, args=(k,)) for k in range(threads)]
    for thread in running:
        thread.start()
    for thread in running:
        thread.join()
    return len(wrong)


def relaxed_in_a_cell_filter(cell_filter, seed):
    """(converged, energy) of Maud and the energy of BFGS, each on
    ``cell_filter`` of a rattled, stretched EMT copper crystal, to fmax 1e-5."""
    crystal = bulk('Cu', cubic=True) * (2, 2, 2)
    crystal.rattle(0.05, seed=seed)
    crystal.set_cell(crystal.cell * 1.03, scale_atoms=True)
    reference = crystal.copy()
    crystal.calc, reference.calc = EMT(), EMT()
    BFGS(cell_filter(reference), logfile=None).run(fmax=1e-5, steps=2000)
    with Maud(cell_filter(crystal), logfile=None) as opt:
        converged = opt.run(fmax=1e-5, steps=2000)
    return converged, crystal.get_potential_energy(), reference.get_potential_energy()


def round_trip_scene(seed: int):
    """A hanging net of 25 points with random ``q``, loads, ``a`` and ``Q``
    (seeded): what every writer must read back as it wrote it."""
    rng = np.random.default_rng(seed)
    atoms = build('hanging_net', 5, seed=seed)
    atoms.calc.set(a=float(rng.uniform(0.2, 1.0)), Q=float(rng.uniform(0.5, 3.0)),
                   q=rng.uniform(0.5, 2.0, len(atoms.calc.springs)),
                   loads=np.c_[np.zeros((len(atoms), 2)), rng.uniform(-1, 0, len(atoms))])
    return atoms
