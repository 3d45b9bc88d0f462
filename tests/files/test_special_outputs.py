"""Outputs land where the user pointed (issue 52, item 1): a symbolic
link's target is written and the link kept, device nodes and named pipes are
written in place (a pipe nobody reads refused at once, never waited on), a
name ending in '/' is a directory, and any legal name takes a temporary
beside it. Special files are made in a temporary directory, never /dev."""

from __future__ import annotations

import os
import stat
import threading
import time
from pathlib import Path

import pytest

from ase_maud.checks import check_writable
from ase_maud.cli.command import main
from ase_maud.files.atomic_replace import NAME_BYTES, replace_text, temporary_beside
from ase_maud.files.output_paths import StagedTrajectory, check_run_files
from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_net
from ase_maud.scenes.catalogue import build


def device(folder: Path) -> Path:
    """A character device that is /dev/null's twin, in ``folder`` (root only)."""
    if os.geteuid() != 0:
        pytest.skip('making a device node needs root')
    path = folder / 'null'
    os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    return path


def relax(folder: Path, *options: str) -> int:
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        return main(['relax', '--scene', 'ring', '--size', '6', '--quiet', *options])
    finally:
        os.chdir(cwd)


@pytest.mark.parametrize('option', ['--forces', '--traj', '--out', '--log'])
def test_a_device_stays_a_device(tmp_path, option):
    null = device(tmp_path)
    name = 'null'
    if option == '--out':   # a net's format is its suffix: a link with one
        os.symlink(null, tmp_path / 'null.json')
        name = 'null.json'
    assert relax(tmp_path, option, name) == 0
    assert stat.S_ISCHR(os.stat(null).st_mode)
    assert not any(p.name.startswith('.null') for p in tmp_path.iterdir())


def test_a_pipe_nobody_reads_is_refused_at_once(tmp_path):
    pipe = tmp_path / 'pipe'
    os.mkfifo(pipe)
    with pytest.raises(OSError, match='nothing reads'):
        replace_text(pipe, 'text\n')
    assert stat.S_ISFIFO(os.stat(pipe).st_mode)
    for option in ('--forces', '--log', '--traj'):
        assert relax(tmp_path, option, 'pipe') == 2
        assert stat.S_ISFIFO(os.stat(pipe).st_mode)


def test_a_pipe_with_a_reader_gets_the_text(tmp_path):
    pipe = tmp_path / 'pipe'
    os.mkfifo(pipe)
    got = []
    opened = threading.Event()

    def read():
        fd = os.open(pipe, os.O_RDONLY | os.O_NONBLOCK)   # a reader, without waiting
        opened.set()
        data = b''
        for _ in range(60000):   # until the text has come (a pipe no one writes reads empty)
            try:
                chunk = os.read(fd, 4096)
            except BlockingIOError:
                chunk = b''
            data += chunk
            if data.endswith(b'b\n'):
                break
            if not chunk:
                time.sleep(0.01)
        os.close(fd)
        got.append(data.decode())
    reader = threading.Thread(target=read)
    reader.start()
    opened.wait(60)
    replace_text(pipe, 'a\nb\n')
    reader.join(60)
    assert got == ['a\nb\n'] and stat.S_ISFIFO(os.stat(pipe).st_mode)


def test_a_trajectory_refuses_a_pipe_before_any_work(tmp_path):
    pipe = tmp_path / 'pipe'
    os.mkfifo(pipe)
    with pytest.raises(ValueError, match='named pipe'):
        StagedTrajectory(pipe)
    with pytest.raises(ValueError, match='named pipe'):
        check_run_files(None, None, pipe)


@pytest.mark.parametrize('dangling', [False, True])
def test_a_link_s_target_is_written_and_the_link_kept(tmp_path, dangling):
    target = tmp_path / 'real.csv'
    if not dangling:
        target.write_text('old\n')
    link = tmp_path / 'link.csv'
    os.symlink('real.csv', link)
    replace_text(link, 'new\n')
    assert link.is_symlink() and target.read_text() == 'new\n'


def test_a_linked_trajectory_and_net(tmp_path):
    os.symlink('real.traj', tmp_path / 'link.traj')
    os.symlink('real.obj', tmp_path / 'link.obj')
    assert relax(tmp_path, '--traj', 'link.traj', '--out', 'link.obj') == 0
    assert (tmp_path / 'link.traj').is_symlink() and (tmp_path / 'link.obj').is_symlink()
    assert len(read_net(tmp_path / 'real.traj')) == len(read_net(tmp_path / 'real.obj')) == 6


def test_a_name_ending_in_a_slash_is_a_directory(tmp_path):
    (tmp_path / 'outdir').mkdir()
    for name in ('outdir/', 'new/'):
        with pytest.raises(ValueError, match='directory'):
            check_writable('--forces', f'{tmp_path}{os.sep}{name}')
        assert relax(tmp_path, '--forces', name) == 2
    assert not (tmp_path / 'new').exists() and not any((tmp_path / 'outdir').iterdir())


def test_the_longest_legal_name_takes_a_temporary(tmp_path):
    for stem in ('f' * (NAME_BYTES - 4), 'é' * ((NAME_BYTES - 5) // 2)):
        path = tmp_path / f'{stem}.obj'
        assert len(path.name.encode()) <= NAME_BYTES
        temporary = temporary_beside(path)
        assert len(temporary.name.encode()) <= NAME_BYTES and temporary.suffix == '.obj'
        temporary.unlink()
        write_net(path, build('ring', 5, seed=1))
        assert len(read_net(path)) == 5


@pytest.mark.skipif(os.geteuid() == 0, reason='root writes in any directory')
def test_a_writable_file_in_a_read_only_directory(tmp_path):
    folder = tmp_path / 'locked'
    folder.mkdir()
    path = folder / 'forces.csv'
    path.write_text('old\n')
    folder.chmod(0o555)
    try:
        check_writable('--forces', path)
        replace_text(path, 'new\n')
        assert path.read_text() == 'new\n'
    finally:
        folder.chmod(0o755)


def test_a_name_whose_edge_list_would_be_too_long_is_refused_first(tmp_path):
    """--out NAME.xyz writes NAME.edges.txt beside it: a 250-byte NAME.xyz
    makes that 256 bytes, refused before any work (it failed after the run)."""
    name = 'n' * 246 + '.xyz'
    assert relax(tmp_path, '--out', name) == 2
    assert not any(tmp_path.iterdir())
    assert relax(tmp_path, '--out', 'n' * 240 + '.xyz') == 0
