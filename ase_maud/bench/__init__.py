"""Speed against error: the Maud optimiser against ASE's and SciPy's.

- :mod:`.optimizers`: the optimisers compared, by name.
- :mod:`.runner`: one optimiser from one start, sampled at every call.
- :mod:`.suite`: every optimiser on every start, written as it goes.
- :mod:`.backends`: cost against accuracy of the calculator's kernels.
- :mod:`.report`: CSV, markdown and PNG output.

On the command line: ``ase-maud bench`` and ``ase-maud backends``.
"""
