"""GLSL sources of the package: one file per shader, built for GLSL 3.30 core or GLSL ES
3.00 (WebGL2) by a small preprocessor.

A source file (``NAME.glsl`` in this folder) is written in the common subset of both
versions (explicit float/int conversions, ``texture``/``textureLod``/``texelFetch``,
``highp`` on samplers) and may ``#include "OTHER.glsl"`` (each file is inlined once, the
first time it is included). :func:`source` resolves the includes and prepends the version
line and, for ES, the default precisions; ``defines`` add ``#define`` lines after them.
"""
from __future__ import annotations

import re
from importlib import resources

__all__ = ["source", "VERSIONS", "SHADERS"]

#: Version name -> header lines.
VERSIONS = {
    "330": ("#version 330 core", "#define MF_GLSL_330 1"),
    "es300": ("#version 300 es", "precision highp float;", "precision highp int;",
              "precision highp sampler2D;", "#define MF_GLSL_ES 1"),
}
_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"\s*$')
_NAME = re.compile(r"^[A-Za-z0-9_.]+$")


def _files() -> list[str]:
    return sorted(p.name[:-5] for p in resources.files(__package__).iterdir() if p.name.endswith(".glsl"))


#: Names accepted by :func:`source` (the ``.glsl`` files of the package).
SHADERS = tuple(_files())


def _read(name: str) -> str:
    if not _NAME.match(name) or name.removesuffix(".glsl") not in SHADERS:
        raise ValueError(f"unknown shader {name!r}; known: {', '.join(SHADERS)}")
    return resources.files(__package__).joinpath(name.removesuffix(".glsl") + ".glsl").read_text()


def _expand(name: str, seen: set[str]) -> list[str]:
    key = name.removesuffix(".glsl")
    if key in seen:
        return []
    seen.add(key)
    out = [f"// ---- {key}.glsl"]
    for line in _read(key).splitlines():
        m = _INCLUDE.match(line)
        out.extend(_expand(m.group(1), seen) if m else [line])
    return out


def source(name: str, version: str = "330", defines: dict | None = None) -> str:
    """The shader ``name`` (``"leadr"``, ``"microfacet"``, ``"tabulated"``, ``"viewer.frag"``,
    ...: :data:`SHADERS`) for ``version`` ``"330"`` (``#version 330 core``) or ``"es300"``
    (``#version 300 es``, WebGL2), includes inlined; ``defines`` maps macro names to values
    (``None``: defined without a value). Library files have no ``main``: append yours.

    Parameters
    ----------
    name : str
        One of :data:`SHADERS` (a trailing ``.glsl`` is accepted).
    version : str
        A key of :data:`VERSIONS`.
    defines : dict, optional
        Macro name -> value (or None).

    Returns
    -------
    str
        The shader text.

    Raises
    ------
    ValueError
        An unknown shader, version or macro name.

    Examples
    --------
    >>> SHADERS
    ('common', 'glints', 'leadr', 'microfacet', 'tabulated', 'viewer.frag', 'viewer.vert')
    >>> text = source("leadr", "es300", defines={"MF_LEVELS": 4})
    >>> text.splitlines()[:2] == list(VERSIONS["es300"][:2]), "#define MF_LEVELS 4" in text
    (True, True)
    >>> text.count("// ---- common.glsl")                 # each include inlined once
    1
    """
    if version not in VERSIONS:
        raise ValueError(f"version must be one of {sorted(VERSIONS)}, got {version!r}")
    lines = list(VERSIONS[version])
    for key, value in (defines or {}).items():
        if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", str(key)):
            raise ValueError(f"invalid macro name {key!r}")
        lines.append(f"#define {key}" + ("" if value is None else f" {value}"))
    return "\n".join(lines + _expand(name, set())) + "\n"
