"""ASE's own optimizer tests, run with Maud (conftest.py says how)."""
