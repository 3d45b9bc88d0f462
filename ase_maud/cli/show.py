"""``ase-maud show``: a picture of a net, or a relaxation as a GIF.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ase_maud.cli.options import judging_fmax, net_options, picture_path, set_net_tables

if TYPE_CHECKING:
    pass


def show_command(args: argparse.Namespace) -> int:
    """``ase-maud show``: exit status 0."""
    # Imported when the command runs, so that ase-maud --help answers at once.
    from ase_maud.files.atomic_replace import replace_with
    from ase_maud.form.pictures import save_animation, save_picture
    from ase_maud.io.nets import read_frames, read_net

    out = picture_path(args)
    style = {'colour': args.color, 'view': args.view, 'ftol': judging_fmax(args)[0]}
    if args.gif:
        frames = read_frames(args.file, **net_options(args))
        for frame in frames:
            set_net_tables(frame, args)
        count = []
        replace_with(out, lambda temporary: count.append(
            save_animation(frames, temporary, fps=args.fps, **style)))
        print(f'wrote {out} ({count[0]} of {len(frames)} frames)')
    else:
        atoms = read_net(args.file, index=args.frame, **net_options(args))
        set_net_tables(atoms, args)
        replace_with(out, lambda temporary: save_picture(atoms, temporary, **style,
                                                         labels=args.labels))
        print(f'wrote {out}')
    return 0
