"""What a mesh or network file holds (:class:`NetData`), and the merge of
its coincident vertices (:func:`merge_coincident`), for the readers of
:mod:`ase_maud.io` (:mod:`.obj`, :mod:`.mesh`, :mod:`.compas`, :mod:`.text`)."""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from ase_maud.physics.topology import spring_components

PathLike = str | os.PathLike


class NetData(NamedTuple):
    """What a mesh or network file holds."""
    positions: np.ndarray     #: (N, 3) points
    springs: np.ndarray       #: (K, 2) 0-based point pairs, each once
    faces: list[list[int]] | np.ndarray  #: rings of point indices (an (F, k) array
    #: where all have k corners); [] for a network
    anchors: list[int]        #: points the file marks fixed


#: Vertices of a file closer than this times the diagonal of their bounding box
#: are one point (an OBJ export from Rhino gives every curve its own copies of
#: its end vertices; STL stores every triangle's corners apart).
MERGE_TOLERANCE = 1e-9



def merge_coincident(points: np.ndarray,
                     tolerance: float = MERGE_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """The point of every one of (N, 3) ``points`` once coincident ones are
    merged, and the merged points.

    Two points closer than ``tolerance`` times the diagonal of the points'
    bounding box are one (and so, in a chain, are all points linked by such
    pairs); a merged point sits where its first copy does, and merged points
    are in the order of their first copies.
    """
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    pairs = cKDTree(points).query_pairs(tolerance * diagonal, output_type='ndarray')
    labels = spring_components(len(points), pairs)
    first = np.full(labels.max() + 1, len(points))
    np.minimum.at(first, labels, np.arange(len(points)))
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return rank[labels], points[first[order]]
