"""ase_maud: the Maud algorithm for points that repel and are tied by springs."""
