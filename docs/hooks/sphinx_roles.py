"""Griffe extension of the API reference (mkdocs.yml): Sphinx roles in docstrings as links.

The docstrings cross-reference with Sphinx roles (``:func:`~sdr_di.api.run_with```), which
mkdocstrings' numpy style shows literally. Here each role becomes an optional cross-reference
of mkdocs-autorefs: a link where the target is rendered on the site, its name in code
otherwise (``~`` shortens the title to the last component, as in Sphinx). A relative target
(``.plugins``, ``run_with``) is looked up from the object's module.
"""

from __future__ import annotations

import html
import re

import griffe

ROLE = re.compile(r":(?:func|class|meth|mod|attr|data|exc|obj|const):`(~?)([^`<>]+)`")


def _target(name: str, module: str) -> str:
    if name.startswith("."):                      # relative to the object's package
        pkg = module.rsplit(".", name.count(".", 0, len(name) - len(name.lstrip("."))))[0]
        return f"{pkg}.{name.lstrip('.')}"
    if "." not in name or not name.startswith("sdr_di"):
        return f"{module}.{name}"
    return name


def roles_to_links(text: str, module: str) -> str:
    """``text`` with every Sphinx role as an optional autorefs link (module notes)."""
    def repl(m: re.Match) -> str:
        short, name = m.group(1) == "~", m.group(2).strip()
        title = name.rsplit(".", 1)[-1] if short else name.lstrip(".")
        ident = _target(name, module)
        return (f'<autoref identifier="{html.escape(ident)}" optional>'
                f"<code>{html.escape(title)}</code></autoref>")
    return ROLE.sub(repl, text)


class SphinxRoles(griffe.Extension):
    """Rewrite the roles of every docstring griffe loads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        if obj.docstring is not None:
            module = obj.module.path if not obj.is_module else obj.path
            obj.docstring.value = roles_to_links(obj.docstring.value, module)
