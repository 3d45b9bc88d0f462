"""Atomic replacement (ase_maud.files.atomic_replace): the temporary
files of killed writers are removed."""

import os

import pytest

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('seed', [1, 2])
def test_temporary_files_of_killed_writers_are_removed(tmp_path, seed):
    # a kill between writing the restart file's temporary and replacing it
    # leaves the temporary; the next run removes those
    # older than a minute and leaves a live writer's alone
    import time

    from ase_maud.files import atomic_replace as atomic
    restart = tmp_path / 'maud.json'
    with Maud(build('hanging_net', 5, seed=seed), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=2)
    old, fresh = tmp_path / '.maud.k1ll3d.tmp.json', tmp_path / '.maud.l1ve.tmp.json'
    for leftover in (old, fresh):
        leftover.write_text('{"format": "half')
    past = time.time() - 2 * atomic.LEFTOVER_SECONDS
    os.utime(old, (past, past))
    with Maud(build('hanging_net', 5, seed=seed), logfile=None, restart=restart) as opt:
        opt.run(fmax=1e-9, steps=2)
    assert not old.exists() and fresh.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        fresh.name, 'maud.json', 'maud.json.arrays']
