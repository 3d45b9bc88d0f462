"""Form finding: member forces, lengths, force densities and support
reactions of a relaxed net (:mod:`~ase_maud.form.member_forces`), the
force-density method (``a = 0``, one sparse solve:
:mod:`~ase_maud.form.force_density`) and pictures of nets
(:mod:`~ase_maud.form.pictures`).
"""
