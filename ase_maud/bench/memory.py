"""The memory of a process and its children (the FMM's worker processes), as
Linux's ``/proc`` gives it: the benchmarks' peak memory."""

from __future__ import annotations


def pss_kb(pid: int) -> int:
    """The proportional set size of process ``pid``, kB: ``Pss`` of
    ``/proc/<pid>/smaps_rollup`` (pages a forked child still shares with its
    parent count once between them); 0 if there is no such process (any
    more) or no ``/proc``."""
    try:
        with open(f'/proc/{pid}/smaps_rollup') as handle:
            return next((int(line.split()[1]) for line in handle
                         if line.startswith('Pss:')), 0)
    except OSError:
        return 0


def tree_pss_kb(pid: int) -> int:
    """:func:`pss_kb` summed over process ``pid`` and its children, kB."""
    try:
        with open(f'/proc/{pid}/task/{pid}/children') as handle:
            pids = [pid, *map(int, handle.read().split())]
    except OSError:
        pids = [pid]
    return sum(map(pss_kb, pids))
