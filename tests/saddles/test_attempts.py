"""The path attempts (ase_maud.saddles.attempts): a failed path keeps where its
band stopped, and the path to a neighbouring minimum skips the minima already
known (the start moved rigidly, a partner whose path failed)."""

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.counting import fresh_copy
from ase_maud.saddles import attempts
from ase_maud.saddles.attempts import path_to_neighbour, path_to_partner
from ase_maud.saddles.between_minima import Transition, reflection
from ase_maud.scenes.families import FAMILIES


def loaded_net(seed: int):
    """A small net of the sagging family relaxed, and its mirror image
    through its supports relaxed: another minimum, of another energy (the
    load pulls one way)."""
    for draw in range(seed, seed + 20):
        net = FAMILIES['sagging_net'](draw, (20, 40))
        assert Maud(net, logfile=None).run(fmax=1e-8, steps=5000)
        try:
            image = reflection(net)
        except ValueError:   # supports on one line: no plane
            continue
        assert Maud(image, logfile=None).run(fmax=1e-8, steps=5000)
        gap = abs(image.get_potential_energy() - net.get_potential_energy())
        if gap > 1e-6 * abs(net.get_potential_energy()):
            return net, image
    pytest.fail('no draw with a mirror minimum of another energy')


@pytest.mark.parametrize('seed', [0, 1])
def test_a_failed_path_keeps_its_bands_highest_image(seed, monkeypatch):
    net, image = loaded_net(seed)
    band = [fresh_copy(net), *(fresh_copy(net) for _ in range(3)), fresh_copy(image)]
    rng = np.random.default_rng(seed)
    for moving in band[1:-1]:
        moving.positions = net.positions + rng.uniform(-0.3, 0.3, net.positions.shape)
    monkeypatch.setattr(attempts, 'saddle_between',
                        lambda *a, **k: Transition(None, band, outcome='it failed'))
    saddle, attempt = path_to_partner(net, image, 1e-6)
    top = max(band[1:-1], key=lambda b: b.get_potential_energy())
    assert saddle is None and attempt.outcome == 'it failed'
    assert np.array_equal(attempt.end, top.positions)
    assert attempt.energy == top.get_potential_energy()


@pytest.mark.parametrize('seed', [2, 3])
def test_the_path_to_a_neighbour_skips_the_minima_already_tried(seed, monkeypatch):
    """An end that relaxes into the mirror minimum: the path to it is taken,
    unless its energy is among those ``tried``; an end at the start gives no
    path."""
    net, image = loaded_net(seed)
    paths = []
    monkeypatch.setattr(attempts, 'path_to_partner', lambda m, p, f: (
        paths.append(p) or (None, attempts.Attempt('path', 0, outcome='stand-in'))))
    shaken = image.positions + np.random.default_rng(seed).uniform(-0.01, 0.01,
                                                                  image.positions.shape)
    held = np.isin(np.arange(len(net)), net.constraints[0].index)
    shaken[held] = image.positions[held]
    _, skipped = path_to_neighbour(net, [net.positions.copy(), shaken], 1e-6, 2000, 1e-8,
                                   tried=(image.get_potential_energy(),))
    assert not paths and skipped.outcome.startswith('none of the 2 points')
    assert skipped.kind == 'neighbour' and 'neighbouring minimum' in skipped.describe()
    assert skipped.calls > 0 and skipped.cpu_s > 0
    _, taken = path_to_neighbour(net, [net.positions.copy(), shaken], 1e-6, 2000, 1e-8)
    assert (taken.kind, taken.outcome, len(paths)) == ('neighbour', 'stand-in', 1)
    assert paths[0].get_potential_energy() == pytest.approx(image.get_potential_energy(),
                                                            rel=1e-8)
