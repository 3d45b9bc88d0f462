"""landscape's arguments checked where they enter (ase_maud.saddles.landscape)."""

import re

import numpy as np
import pytest

from ase_maud.saddles.landscape import landscape
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('keyword, value, accepted', [
    ('energy_rtol', -1, 'a positive finite number'),
    ('energy_rtol', np.nan, 'a positive finite number'),
    ('distance_atol', np.nan, 'a finite number >= 0'),
    ('distance_atol', -1e-3, 'a finite number >= 0'),
    ('modes', -1, 'a whole number >= 0'),
    ('modes', 1.5, 'a whole number >= 0'),
    ('fmax', 0, 'a positive finite number')])
def test_landscape_checks_its_arguments(keyword, value, accepted):
    with pytest.raises(ValueError, match=f'^{keyword} must be {re.escape(accepted)}'):
        landscape(build('ring', 6), **{keyword: value})
