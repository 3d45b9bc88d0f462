"""Issue 30, left open: a restart file damaged by hand field by field. Its
scene, which its run wrote whole, is checked key by key: a key taken out had
switched the check of that key off (the file was taken for the atoms')."""

import json

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_restart_file_missing_a_scene_key_is_refused(tmp_path, seed):
    restart = tmp_path / 'm.json'
    with Maud(build('hanging_net', 4, seed=seed), restart=restart, logfile=None) as opt:
        opt.run(fmax=1e-9, steps=3)
    document = json.loads(restart.read_text())
    keys = sorted(document['scene'])
    assert len(keys) >= 10   # points, fixed points, springs, a, Q, dim, ... with CRCs
    key = keys[np.random.default_rng(seed).integers(len(keys))]
    del document['scene'][key]
    restart.write_text(json.dumps(document))
    with pytest.raises(ValueError, match=f"is of another scene: its scene has no '{key}'"):
        Maud(build('hanging_net', 4, seed=seed), restart=restart, logfile=None)
    document['scene'] = {}
    restart.write_text(json.dumps(document))
    with pytest.raises(ValueError, match='its scene has no'):
        Maud(build('hanging_net', 4, seed=seed), restart=restart, logfile=None)
