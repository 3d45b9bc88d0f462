"""Command-line values checked where they enter (ase_maud.cli.options): a frame
past the end, loads beyond float64; each a one-line error."""

from helpers import one_line_error


def test_frame_on_the_command_line(capsys, four_frames):
    error = one_line_error(capsys, ['classify', four_frames[0], '--frame', '5'])
    assert 'no frame 5: the file holds 4 frames' in error


def test_loads_beyond_float64_are_named(capsys, tmp_path):
    error = one_line_error(capsys, ['relax', '--scene', 'ring', '--size', '8', '--load',
                                    '1e308', '0', '0', '--traj', tmp_path / 'o.traj',
                                    '--quiet'])
    assert 'the energy of the loads, -sum p.x, overflows float64 (loads up to 1e+308' in error
