"""The parameter reference of the Mitsuba plugins, generated from the plugin classes'
docstrings (as Mitsuba generates its own plugin documentation from its sources).

Each plugin class (:data:`PLUGIN_CLASSES`) carries one table in its docstring, a Markdown
table with the header :data:`HEADER` (``| name | type | default | meaning |``), one row per
parameter (the name in backquotes; no ``|`` inside a cell). :func:`parameter_table` parses
it, :func:`plugin_reference` returns the Markdown of all plugins. The docstrings are read
from the source files with :mod:`ast`: neither Mitsuba nor a variant is needed.

Examples
--------
>>> from microfacet.mitsuba.reference import HEADER, PLUGIN_CLASSES, parameter_table
>>> list(PLUGIN_CLASSES)
['mf_microfacet', 'mf_fitted', 'mf_leadr', 'mf_glints']
>>> PLUGIN_CLASSES["mf_leadr"], HEADER
(('leadr', 'LeadrBSDF'), ('name', 'type', 'default', 'meaning'))
>>> [p.name for p in parameter_table("mf_glints")][:3]
['filename', 'exact', 'g2']
"""
from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import NamedTuple

__all__ = ["PLUGIN_CLASSES", "HEADER", "Parameter", "class_docstring", "parse_table", "parameter_table",
           "plugin_reference"]

#: Plugin name -> (module of :mod:`microfacet.mitsuba`, plugin class).
PLUGIN_CLASSES = {"mf_microfacet": ("bsdf", "MicrofacetBSDF"), "mf_fitted": ("fitted", "FittedBSDF"),
                  "mf_leadr": ("leadr", "LeadrBSDF"), "mf_glints": ("glints", "GlintsBSDF")}
#: The columns of a parameter table.
HEADER = ("name", "type", "default", "meaning")
_ROLE = re.compile(r":\w+:`(~?)([^`]+)`")


class Parameter(NamedTuple):
    """One row of a plugin's parameter table.

    ``default`` is as written: ``required``, ``none``, a number or a backquoted word.

    Attributes
    ----------
    name : str
        The parameter's name.
    type : str
        Its type as written in the table (``float``, ``texture``, ``string``...).
    default : str
        Its default as written: ``required``, ``none``, a number or a backquoted word.
    meaning : str
        What it is.

    Examples
    --------
    >>> from microfacet.mitsuba.reference import Parameter, parameter_table
    >>> p = parameter_table("mf_fitted")[0]
    >>> p.name, p.type, p.default
    ('filename', 'string', 'required')
    >>> Parameter("alpha", "float", "0.1", "roughness").default
    '0.1'
    """
    name: str
    type: str
    default: str
    meaning: str


def class_docstring(plugin: str) -> str:
    """The docstring of a plugin's class (:data:`PLUGIN_CLASSES`), read from its source.

    Parameters
    ----------
    plugin : str
        A plugin name (``"mf_microfacet"``, ...).

    Returns
    -------
    str
        The class docstring (dedented, as :func:`ast.get_docstring`).

    Raises
    ------
    ValueError
        Naming an unknown plugin, or a module without the plugin's class.

    Examples
    --------
    >>> from microfacet.mitsuba.reference import class_docstring
    >>> class_docstring("mf_leadr").split(":")[0]
    'A LEADR moment pyramid of ``microfacet bake`` over a base material'
    >>> class_docstring("roughconductor")
    Traceback (most recent call last):
    ...
    ValueError: plugin must be one of mf_microfacet, mf_fitted, mf_leadr, mf_glints, got 'roughconductor'
    """
    if plugin not in PLUGIN_CLASSES:
        raise ValueError(f"plugin must be one of {', '.join(PLUGIN_CLASSES)}, got {plugin!r}")
    module, cls = PLUGIN_CLASSES[plugin]
    path = Path(__file__).with_name(f"{module}.py")
    for node in ast.parse(path.read_text(encoding="utf-8"), str(path)).body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            return ast.get_docstring(node) or ""
    raise ValueError(f"{plugin}: no class {cls} in {path}")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def parse_table(doc: str, where: str = "docstring") -> list[Parameter]:
    r"""The parameter rows of the one table of a docstring.

    Parameters
    ----------
    doc : str
        A docstring with one table whose header is :data:`HEADER`.
    where : str, optional
        What the docstring is, for errors (e.g. the plugin).

    Returns
    -------
    list of Parameter
        The rows, in order; the table ends at the first line that does not start with ``|``.

    Raises
    ------
    ValueError
        Naming ``where`` when the header is missing or repeated, or a row does not have four
        cells or a backquoted name.

    Examples
    --------
    >>> from microfacet.mitsuba.reference import parse_table
    >>> doc = "\n".join(["A plugin.", "", "| name | type | default | meaning |", "|---|---|---|---|",
    ...                  "| `alpha` | float | 0.1 | roughness |"])
    >>> parse_table(doc, "mf_example")
    [Parameter(name='alpha', type='float', default='0.1', meaning='roughness')]
    >>> parse_table("No table.", "mf_example")
    Traceback (most recent call last):
    ...
    ValueError: mf_example: expected one table with header | name | type | default | meaning |, found 0
    """
    lines = [ln.strip() for ln in doc.splitlines()]
    header = [i for i, ln in enumerate(lines) if ln.startswith("|") and tuple(_cells(ln)) == HEADER]
    if len(header) != 1:
        raise ValueError(f"{where}: expected one table with header | {' | '.join(HEADER)} |, found {len(header)}")
    rows = []
    for ln in lines[header[0] + 2:]:
        if not ln.startswith("|"):
            break
        cells = _cells(ln)
        if len(cells) != 4 or not re.fullmatch(r"`\w+`", cells[0]):
            raise ValueError(f"{where}: malformed parameter row {ln!r}")
        rows.append(Parameter(cells[0].strip("`"), *cells[1:]))
    return rows


def parameter_table(plugin: str) -> list[Parameter]:
    """The parameters of a plugin, as documented in its class docstring.

    Parameters
    ----------
    plugin : str
        A plugin of :data:`PLUGIN_CLASSES` (``"mf_microfacet"``, ...).

    Returns
    -------
    list of Parameter
        Its rows (:func:`parse_table`).

    Examples
    --------
    >>> from microfacet.mitsuba.reference import parameter_table
    >>> rows = {p.name: p for p in parameter_table("mf_microfacet")}
    >>> rows["distribution"].default, rows["alpha"].type
    ('`beckmann`', 'float or texture')
    """
    return parse_table(class_docstring(plugin), plugin)


def _prose(doc: str) -> str:
    """The docstring's text before its table, in one paragraph per blank-line block, with
    reST roles and double backquotes made Markdown code."""
    text = doc.split("| name |")[0].strip()
    paragraphs = [" ".join(p.split()) for p in re.split(r"\n\s*\n", text) if p.strip()]
    def code(m):               # :class:`~a.B` -> `B`, :func:`a.f` -> `a.f`
        return f"`{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}`"
    return "\n\n".join(_ROLE.sub(code, p).replace("``", "`") for p in paragraphs)


def plugin_reference() -> str:
    """Markdown of every plugin's parameters.

    Per plugin of :data:`PLUGIN_CLASSES`, a ``## `name``` section with its class docstring's
    text (reST roles made Markdown code) and its table (:func:`parameter_table`).

    Returns
    -------
    str
        The Markdown page body.

    Examples
    --------
    >>> from microfacet.mitsuba import plugin_reference
    >>> text = plugin_reference()
    >>> text.splitlines()[0]
    '## `mf_microfacet`'
    >>> [line for line in text.splitlines() if line.startswith("## ")][1:]
    ['## `mf_fitted`', '## `mf_leadr`', '## `mf_glints`']
    >>> "| `filename` | string | required | the pyramid EXR of `microfacet bake` |" in text
    True
    """
    out = []
    for plugin in PLUGIN_CLASSES:
        doc = class_docstring(plugin)
        rows = [f"| `{p.name}` | {p.type} | {p.default} | {p.meaning} |" for p in parse_table(doc, plugin)]
        out += [f"## `{plugin}`", "", _prose(doc), "", "| " + " | ".join(HEADER) + " |", "|---|---|---|---|",
                *rows, ""]
    return "\n".join(out)
