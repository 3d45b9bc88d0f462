"""Non-finite results of any calculator (ase_maud.bench.doubles.PoisonedCalculator)
or stiffness stop the run at good positions: no non-finite value reaches the user."""

import numpy as np
import pytest
from ase.calculators.calculator import all_changes
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron
from ase.io import read

from ase_maud import Maud, MaudCalculator, MaudError
from ase_maud.bench.doubles import PoisonedCalculator
from ase_maud.files.trajectory import last_frame
from ase_maud.scenes.catalogue import build

# -- 2. non-finite results of any calculator (ase_maud.bench.doubles.PoisonedCalculator) ---------


def emt_cluster():
    atoms = Icosahedron('Cu', 2)
    atoms.rattle(0.05, seed=1)
    return atoms, EMT()


def maud_net():
    atoms = build('hanging_net', 5, seed=1)
    return atoms, MaudCalculator(**atoms.calc.parameters)


@pytest.mark.parametrize('scene', [emt_cluster, maud_net])
@pytest.mark.parametrize('what', ['energy', 'forces'])
@pytest.mark.parametrize('value', [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize('call', [1, 4])
def test_non_finite_results_stop_the_run_at_good_positions(tmp_path, scene, what, value,
                                                           call):
    atoms, inner = scene()
    atoms.calc = PoisonedCalculator(inner, call, what, value)
    traj = tmp_path / 'run.traj'
    start = atoms.positions.copy()
    step = call - 1   # one calculator call per step
    text = ('a non-finite energy' if what == 'energy'
            else rf'non-finite forces \(atom 6: \[{value}, 0, 0\]\)')
    where = ('the atoms are at their start positions' if step == 0
             else f'positions restored to step {step - 1}')
    with pytest.raises(MaudError, match=f'calculator returned {text}.* at step {step}; '
                                        f'{where}$'):
        with Maud(atoms, logfile=None, trajectory=traj) as opt:
            opt.run(fmax=1e-6)
    assert np.isfinite(atoms.positions).all()
    if step == 0:
        assert np.array_equal(atoms.positions, start)
        assert last_frame(traj) is None
    else:
        frames = read(traj, ':')
        assert len(frames) == step   # frames 0 .. step - 1, none of the bad step
        assert all(np.isfinite(f.get_potential_energy()) and np.isfinite(f.get_forces()).all()
                   for f in frames)
        assert np.array_equal(atoms.positions, frames[-1].positions)


class PoisonedHessian(MaudCalculator):
    """MaudCalculator whose third call returns a Hessian with a NaN."""

    calls = 0

    def calculate(self, atoms=None, properties=('energy',), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.calls += 1
        if self.calls == 3:
            self.results['hessian'][2, 3] = self.results['hessian'][3, 2] = np.nan


def test_non_finite_stiffness_stops_the_run():
    atoms = build('ring', 8, seed=2)
    atoms.calc = PoisonedHessian(**atoms.calc.parameters)
    with pytest.raises(MaudError, match=r'no finite step from step 2: the calculator '
                                        r'returned a non-finite hessian \(entry \[2, 3\]'):
        with Maud(atoms, logfile=None) as opt:
            opt.run(fmax=1e-8)
    assert np.isfinite(atoms.positions).all()
