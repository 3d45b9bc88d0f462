"""Nets in and out of files: :func:`read_net` and :func:`write_net`
(:mod:`~ase_maud.io.nets`) over one reader and writer per format: OBJ, COMPAS
JSON, PLY/STL/OFF/VTK/VTU through meshio, points plus edge lists, ASE's own
formats; per-point and per-edge tables (loads, force densities).
"""

from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import (
    check_net_path,
    default_a,
    net_format,
    read_frames,
    read_net,
    set_tables,
)
from ase_maud.old_paths import old_names

__all__ = ['read_net', 'read_frames', 'write_net', 'net_format', 'set_tables', 'default_a',
           'check_net_path']
#: The names of ase_maud 0.1's ``ase_maud.io`` module, handed on with a warning.
__getattr__ = old_names('io')
