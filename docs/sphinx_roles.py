"""A griffe extension for the API pages: Sphinx roles in docstrings (``:class:`X```) as code (```X```).

piga's docstrings cross-reference in Sphinx's reST roles; mkdocstrings reads Markdown, where a role
would show as literal text.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):`~?([^`]+)`")


class SphinxRoles(griffe.Extension):
    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(r"`\1`", obj.docstring.value)
