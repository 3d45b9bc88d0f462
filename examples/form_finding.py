"""Form finding of a hanging canopy: member forces and support reactions.

The shipped net ``examples/nets/canopy.obj`` (10 x 10 points, an opening in
the middle) hangs from its outer rim under its self-weight; the cables round
the opening get a higher force density. With ``a = 0`` (the default for a net
whose supports hold it) the form is the force-density equilibrium of its
members and loads: one sparse solve. The example prints the largest member
force and checks that the reactions balance the load, then writes the
forces as CSV, the net as COMPAS JSON (supports, forces, reactions) and a
picture. Run:

    python examples/form_finding.py [--weight 0.2] [--opening-q 3]

The same from the command line, with the force densities from a CSV table:

    ase-maud relax examples/nets/canopy.obj --fix outer --load 0 0 -0.2 \\
        --forces forces.csv --out canopy.json
"""

import argparse
from pathlib import Path

import numpy as np

from ase_maud.form.force_density import solve_force_density
from ase_maud.form.member_forces import describe_result, form_result, write_forces_csv
from ase_maud.form.pictures import save_picture
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.io.obj import read_obj
from ase_maud.physics.topology import boundary_vertices, outer_rim

NET = Path(__file__).parent / 'nets' / 'canopy.obj'


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--weight', type=float, default=0.2,
                        help='load on every free point, force units, downwards')
    parser.add_argument('--opening-q', type=float, default=3.0,
                        help='force density multiplier of the cables round the opening')
    args = parser.parse_args()

    atoms = read_net(NET, fixed='outer', load=(0.0, 0.0, -args.weight))
    print(f'{NET.name}: {len(atoms)} points, {len(atoms.calc.springs)} members, '
          f'{len(atoms.constraints[0].index)} supports, a = {atoms.calc.parameters["a"]}')

    # the opening's rim: on the boundary, not on the outer rim
    faces = read_obj(NET).faces
    rim = np.setdiff1d(boundary_vertices(faces), outer_rim(faces, atoms.positions))
    springs = atoms.calc.springs
    around = np.isin(springs, rim).all(axis=1)
    atoms.calc.set(q=np.where(around, args.opening_q, 1.0))
    print(f'{around.sum()} cables round the opening at q = {args.opening_q}')

    solve_force_density(atoms)
    result = form_result(atoms)
    print(describe_result(result))
    total_load = atoms.calc.potential.loads.sum(axis=0)
    balance = np.abs(result.reaction_sum + total_load).max()
    print(f'reactions + loads = {balance:.2e} (of a load of {np.abs(total_load).sum():.4g})')
    print(f'sag at the opening: {-atoms.positions[rim, 2].mean():.4g}')

    write_forces_csv('canopy_forces.csv', result)
    write_net('canopy.json', atoms, result=result)
    save_picture(atoms, 'canopy.png', view='iso')
    print('wrote canopy_forces.csv, canopy.json, canopy.png')


if __name__ == '__main__':
    main()
