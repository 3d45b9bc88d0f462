"""A griffe extension for the API reference of the docs site (``mkdocs.yml``).

The docstrings are numpy style with Sphinx cross-reference roles
(``:class:`~.base.Backend```, ``:func:`numba_cache_dir```) and reST literal
markers (``Energy::``). Markdown has neither: this extension rewrites each role
as inline code (the last dotted name for a ``~`` target, else the target
without leading dots) and ``::`` at a line's end as ``:``, so the pages read
cleanly; the docstrings themselves stay as they are.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

#: A Sphinx role such as :class:`~.base.Backend` or :py:func:`name`.
ROLE = re.compile(r':(?:py:)?[a-z]+:`(~?)([^`]+)`')
#: A reST literal-block marker at the end of a line.
LITERAL = re.compile(r'::$', re.MULTILINE)


def _code(match: re.Match[str]) -> str:
    short, target = match.groups()
    target = target.lstrip('.')
    return f'`{target.rsplit(".", 1)[-1] if short else target}`'


class SphinxRoles(griffe.Extension):
    """Rewrite Sphinx roles and reST ``::`` markers in every docstring."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            text = ROLE.sub(_code, obj.docstring.value)
            obj.docstring.value = LITERAL.sub(':', text)
