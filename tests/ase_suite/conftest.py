"""ASE's own optimizer tests, run with Maud (the modules of this folder).

Each module imports the tests of one module of the installed ``ase`` package
(``ase/test``), unchanged; only their fixtures are overridden here and there
(``optcls`` gives Maud, ``testdir`` a fresh directory) and, where a test names
an optimizer inside itself, that name is Maud while the test runs
(:func:`maud_everywhere`). A change of ASE's optimizer contract shows up here.
A test that cannot apply to Maud is listed, with the reason, in the module
that would import it, and skipped with it.
"""

from __future__ import annotations

import sys

import pytest

from ase_maud import Maud

#: The optimizer names ASE's tests use inside a test; each is Maud here.
REPLACED = ('BFGS', 'QuasiNewton', 'FIRE', 'LBFGS', 'BFGSLineSearch', 'CellAwareBFGS')


@pytest.fixture(autouse=True)
def maud_everywhere(request, monkeypatch):
    """Every optimizer the test's own ASE module names is Maud."""
    module = sys.modules[request.function.__module__]
    for name in REPLACED:
        if hasattr(module, name):
            monkeypatch.setattr(module, name, Maud)


@pytest.fixture
def testdir(tmp_path, monkeypatch):
    """ASE's ``testdir``: the test runs in a fresh directory."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture
def optcls():
    return Maud


@pytest.fixture
def kwargs():
    return {}
