"""A Griffe extension for the API reference: the docstrings' Sphinx roles
(:func:`name`, :class:`~pkg.Name`, ...) become inline code (`name`, `Name`), so the reST-ish
docstrings render as Markdown without the role markers."""

import re

import griffe

ROLE = re.compile(r":(?:func|class|data|meth|mod|attr|exc|obj|const):`(~?)([^`]+)`")


def _code(match: re.Match) -> str:
    """A role's target as inline code, its last part alone after a ``~`` (as Sphinx shows it)."""
    short, target = match.groups()
    return f"`{target.rsplit('.', 1)[-1] if short else target}`"


def strip_roles(text: str) -> str:
    """``text`` with every Sphinx role replaced by inline code of its target."""
    return ROLE.sub(_code, text)


class SphinxRoles(griffe.Extension):
    """Rewrites every docstring the reference renders."""

    def on_object(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = strip_roles(obj.docstring.value)
