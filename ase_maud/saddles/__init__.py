"""Saddles and the landscape around a minimum: :func:`~ase_maud.saddles.search.search_saddles`
(attempts from a minimum: :mod:`~ase_maud.saddles.attempts`), the saddle between
two minima (:mod:`~ase_maud.saddles.between_minima`: a band, the mirror image
of a net), and :func:`~ase_maud.saddles.landscape.landscape` (saddles and the
minima they join, on dask workers if given a client); and the starts of searches,
a minimum moved along its lowest mode (:mod:`~ase_maud.saddles.starts`).
"""
