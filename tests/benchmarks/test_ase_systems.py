"""benchmarks/ase_systems.py: every image counted, hops capped, and the race."""

import runpy

import numpy as np
import pytest

from helpers import ROOT


def test_ase_systems_tool_counts_every_image_and_caps_hops():
    """benchmarks/ase_systems.py: L-BFGS-B relaxes a cell filter (its rows are
    positions) and has no column for a band; a band's calls are summed over
    its images; BasinHopping's local relaxations are capped at --steps."""
    from ase.optimize import BFGS

    from ase_maud import Maud
    tool = runpy.run_path(str(ROOT / 'benchmarks' / 'ase_systems.py'))
    calls, _, energy, converged = tool['relax']('Au8 cell', 1, tool['scipy_lbfgsb'], 0.01, 200)
    assert converged is True and calls > 1 and energy < 0.0
    assert tool['relax']('Al/Au NEB', 1, tool['scipy_lbfgsb'], 0.05, 200) is None
    calls, _, _, converged = tool['relax']('Al/Au NEB', 1, Maud, 0.05, 3)
    assert not converged and calls == 3 * 4   # 3 inner images, 4 evaluations each
    calls, _, lowest = tool['basin']('LJ13', 1, BFGS, 1, 0.01, 5)
    assert lowest.endswith('(2 not converged in 5 steps)')


@pytest.mark.parametrize('seed', [int(s) for s in np.random.default_rng(32).integers(0, 10**4, 2)])
def test_ase_systems_race_reaches_a_chain_own_lowest_at_its_own_calls(seed):
    """benchmarks/ase_systems.py --race: racing BFGS's own BasinHopping chain (the
    same seed, so the same moves) to its lowest energy reaches it within its
    calls, at the relaxation that first found it; an unreachable target stops
    once the calls are spent."""
    from ase.optimize import BFGS
    tool = runpy.run_path(str(ROOT / 'benchmarks' / 'ase_systems.py'))
    calls, _, lowest = tool['basin']('LJ7', seed, BFGS, 3, 0.01, 2000)
    target = float(lowest.split()[0])
    reached, spent, cpu, hops, best = tool['race']('LJ7', seed, BFGS, calls, target, 0.01, 2000)
    assert reached == spent and 0 < reached <= calls and hops <= 3 and cpu > 0
    assert abs(best - target) <= 1e-3
    reached, spent, _, hops, best = tool['race']('LJ7', seed, BFGS, calls, target - 10, 0.01,
                                                   2000)
    assert reached is None and spent >= calls and best >= target - 1e-3
