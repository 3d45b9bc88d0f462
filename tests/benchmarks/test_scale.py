"""benchmarks/scale.py: its memory figure counts the FMM's worker processes
(children of the measuring process), each shared page once."""

import multiprocessing
import os
import runpy
import sys

import numpy as np
import pytest

from ase_maud.bench.memory import pss_kb

from helpers import ROOT

TOOL = runpy.run_path(str(ROOT / 'benchmarks' / 'scale.py'))

pytestmark = pytest.mark.skipif(not sys.platform.startswith('linux'),
                                reason='the process tree is read from /proc')


def _hold(megabytes, ready, release):
    """A child: touch ``megabytes`` of its own, say so, wait to be released."""
    block = np.ones(megabytes * 2**20 // 8)
    ready.set()
    release.wait(120)
    assert block.sum() > 0


@pytest.mark.parametrize('megabytes', [150, 300])
def test_the_peak_counts_a_child_process(megabytes):
    context = multiprocessing.get_context('fork')
    ready, release = context.Event(), context.Event()
    memory = TOOL['TreeMemory'](interval=0.05)
    own = pss_kb(os.getpid()) / 1024
    child = context.Process(target=_hold, args=(megabytes, ready, release))
    child.start()
    try:
        assert ready.wait(120)
        # wait for a sample taken while the child holds its block
        for _ in range(2400):
            if memory.peak_kb / 1024 > own + 0.9 * megabytes:
                break
            release.wait(0.05)
    finally:
        release.set()
        child.join()
    peak = memory.peak_mb()
    assert own + 0.9 * megabytes < peak < own + megabytes + 200
