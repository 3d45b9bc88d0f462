"""Calculator doubles: an ASE calculator that fails at a chosen call
(:class:`PoisonedCalculator`), a MaudCalculator whose energy carries a
declared noise (:class:`NoisyEnergy`), and any calculator whose energy
carries noise nobody declares (:class:`UndeclaredNoise`).

They are the hard inputs the tests give Maud, and the ones
``benchmarks/noisy_energy.py`` and ``dev/hostile_sweep.py`` measure it on: they
live in the package so that tests and scripts import the same classes (no
script reaches into ``tests/``). Nothing else in the package uses them.
"""

import numpy as np
from ase.calculators.calculator import Calculator, all_changes

from ase_maud.calculator.maud_calculator import MaudCalculator


class PoisonedCalculator(Calculator):
    """Any ASE calculator ``inner``, except that its call number ``call``
    returns ``value`` (NaN or inf, say) as the energy (``what='energy'``) or
    as the x force on atom ``atom`` (``what='forces'``): the hard input of a
    calculator that fails mid-run."""

    def __init__(self, inner: Calculator, call: int, what: str, value: float,
                 atom: int = 6) -> None:
        super().__init__()
        self.implemented_properties = inner.implemented_properties
        self.inner, self.call, self.what, self.value = inner, call, what, value
        self.atom, self.calls = atom, 0

    def calculate(self, atoms=None, properties=('energy',),
                  system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        self.calls += 1
        copy = self.atoms.copy()
        self.results = {name: np.copy(self.inner.get_property(name, copy))
                        for name in {'energy', 'free_energy', 'forces', *properties}}
        if self.calls == self.call:
            if self.what == 'energy':
                self.results['energy'] = self.results['free_energy'] = self.value
            else:
                self.results['forces'][self.atom] = [self.value, 0.0, 0.0]


class NoisyEnergy(MaudCalculator):
    """A MaudCalculator (exact direct sum) whose energy carries seeded
    random noise, uniform in ``[-noise, noise] |E|``, which it declares
    (unless ``declare`` is False) as the error of its energy
    (``last_energy_error``, what :func:`ase_maud.calculator.accuracy.energy_noise`
    reads); its forces are exact. Each call's exact energy is kept in ``exact``."""

    def __init__(self, noise: float, seed: int, declare: bool = True,
                 **parameters) -> None:
        super().__init__(**{**parameters, 'backend': 'numba'})
        self.noise, self.rng, self.exact = noise, np.random.default_rng(seed), []
        self.declare = declare

    def calculate(self, atoms=None, properties=('energy',),
                  system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        energy = self.results['energy']
        self.exact.append(energy)
        energy += self.noise * abs(energy) * self.rng.uniform(-1.0, 1.0)
        self.results['energy'] = self.results['free_energy'] = energy
        if self.declare:
            self.last_energy_error = max(self.last_energy_error, self.noise * abs(self.exact[-1]))


class UndeclaredNoise(Calculator):
    """``inner``'s energy with seeded noise of ``noise`` (relative, uniform
    in ``[-noise, noise] |E|``) that no one declares, and its exact forces:
    a plain ASE calculator, so Maud learns the noise from the steps (a
    MaudCalculator declares its own and is taken at its word)."""
    implemented_properties = ['energy', 'forces']

    def __init__(self, inner: Calculator, noise: float, seed: int) -> None:
        super().__init__()
        self.inner, self.noise = inner, noise
        self.rng = np.random.default_rng(seed)

    def calculate(self, atoms=None, properties=('energy',), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        copy = atoms.copy()
        copy.calc = self.inner
        energy = copy.get_potential_energy()
        self.results = {'energy': energy + self.noise * abs(energy) * self.rng.uniform(-1, 1),
                        'forces': copy.get_forces()}
