"""The net file formats :mod:`ase_maud.io` reads and writes, one module each
(:mod:`.obj`, :mod:`.compas`; :mod:`.text` for the line-by-line text files),
and what a mesh or network file holds (:class:`NetData`)."""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

PathLike = str | os.PathLike


class NetData(NamedTuple):
    """What a mesh or network file holds."""
    positions: np.ndarray     #: (N, 3) points
    springs: np.ndarray       #: (K, 2) 0-based point pairs, each once
    faces: list[list[int]] | np.ndarray  #: rings of point indices (an (F, k) array
    #: where all have k corners); [] for a network
    anchors: list[int]        #: points the file marks fixed
