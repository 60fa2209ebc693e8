"""The plugins' parameter tables (:mod:`microfacet.mitsuba.reference`) against the code that
reads the parameters.

* :func:`plugin_reference` has a section and a table for every plugin of ``PLUGINS``.
* Every parameter name a plugin's ``__init__`` reads from its ``mi.Properties`` (found in the
  source with :mod:`ast`, following the calls into the package's readers) is in its table.
* Every documented name is read: a plugin built with that parameter (its documented default,
  or an example value) marks it queried (``scalar_rgb``).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import microfacet as mf
import microfacet.mitsuba as mfm
from microfacet.mitsuba.reference import PLUGIN_CLASSES, parameter_table, parse_table, plugin_reference

PACKAGE = Path(mfm.__file__).parent


def test_reference_has_a_table_per_plugin():
    text = plugin_reference()
    assert set(PLUGIN_CLASSES) == set(mfm.PLUGINS)
    for plugin in mfm.PLUGINS:
        rows = parameter_table(plugin)
        names = [p.name for p in rows]
        assert len(rows) >= 3 and len(set(names)) == len(names), plugin
        assert f"## `{plugin}`" in text
        for p in rows:
            assert f"| `{p.name}` | {p.type} | {p.default} |" in text
            assert p.type and p.default and p.meaning, (plugin, p)


def test_malformed_tables_are_refused():
    good = "x\n\n| name | type | default | meaning |\n|---|---|---|---|\n| `a` | float | 1 | the a |\n"
    assert [p.name for p in parse_table(good)] == ["a"]
    with pytest.raises(ValueError, match="malformed parameter row"):
        parse_table(good + "| `b` | float | 1 |\n")
    with pytest.raises(ValueError, match="expected one table"):
        parse_table("no table here", "somewhere")


# ------------------------------------------------------------------ what the code reads
class _Module:
    """Functions of one module of the package (by name; methods as ``Class.name``), the
    names it imports from sibling modules, and the keys of ``FRESNEL_KEYS``."""

    def __init__(self, name: str):
        self.tree = ast.parse((PACKAGE / f"{name}.py").read_text())
        self.functions: dict[str, ast.AST] = {}
        self.imported: dict[str, str] = {}
        for node in self.tree.body:
            if isinstance(node, ast.FunctionDef):
                self.functions[node.name] = node
            elif isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.FunctionDef):
                        self.functions[f"{node.name}.{item.name}"] = item
            elif isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
                for alias in node.names:
                    self.imported[alias.asname or alias.name] = node.module


def _fresnel_keys() -> set[str]:
    for node in ast.parse((PACKAGE / "properties.py").read_text()).body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "FRESNEL_KEYS":
            return set(ast.literal_eval(node.value))
    raise AssertionError("properties.FRESNEL_KEYS not found")


def _is_props(node) -> bool:
    return isinstance(node, ast.Name) and node.id == "props"


def _strings(nodes) -> set[str]:
    return {n.value for n in nodes if isinstance(n, ast.Constant) and isinstance(n.value, str)}


def _reads(fn) -> tuple[set[str], list[ast.expr]]:
    """Parameter names ``fn`` reads from ``props`` (``props["x"]``, ``props.get("x")``,
    ``"x" in props``, ``reader(props, "x", ...)``; names in ``FRESNEL_KEYS``) and the
    functions it calls."""
    names, calls = set(), []
    for node in ast.walk(fn):
        if isinstance(node, ast.Subscript) and _is_props(node.value):
            names |= _strings([node.slice])
        elif isinstance(node, ast.Compare) and any(_is_props(c) for c in node.comparators):
            names |= _strings([node.left])
        elif isinstance(node, ast.Call):
            calls.append(node.func)
            args = node.args
            if isinstance(node.func, ast.Attribute) and _is_props(node.func.value):
                names |= _strings(args[:1])                 # props.get("x", default)
            for i, a in enumerate(args[:-1]):
                if _is_props(a):
                    names |= _strings([args[i + 1]])        # reader(props, "x", default, ...)
        if isinstance(node, (ast.Name, ast.Attribute)) and getattr(node, "id", getattr(node, "attr", "")) \
                == "FRESNEL_KEYS":
            names |= _fresnel_keys()
    return names, calls


def names_read(plugin: str) -> set[str]:
    """Every parameter name read by ``plugin``'s ``__init__`` and the package functions it
    calls (resolved by name within a module and through ``from .module import name``)."""
    module, cls = PLUGIN_CLASSES[plugin]
    modules: dict[str, _Module] = {}
    todo, seen, names = [(module, f"{cls}.__init__")], set(), set()
    while todo:
        mod, fn = todo.pop()
        if (mod, fn) in seen:
            continue
        seen.add((mod, fn))
        m = modules.setdefault(mod, _Module(mod))
        if fn not in m.functions:           # a class or constant imported from a sibling
            continue
        found, calls = _reads(m.functions[fn])
        names |= found
        for call in calls:
            callee = getattr(call, "id", None)
            if callee in m.functions:
                todo.append((mod, callee))
            elif callee in m.imported and (PACKAGE / f"{m.imported[callee]}.py").exists():
                todo.append((m.imported[callee], callee))
    return names


@pytest.mark.parametrize("plugin", list(PLUGIN_CLASSES))
def test_every_parameter_read_is_documented(plugin):
    read = names_read(plugin)
    assert "filename" in read or plugin == "mf_microfacet"     # the scan follows the readers
    documented = {p.name for p in parameter_table(plugin)}
    assert read <= documented, f"{plugin} reads undocumented parameters: {sorted(read - documented)}"


# ------------------------------------------------------------------ every documented name is read
mi = pytest.importorskip("mitsuba", reason="the Mitsuba plugins need the optional `mitsuba` package")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A fit, a LEADR pyramid and a glint microsurface, small."""
    import numpy as np
    d = tmp_path_factory.mktemp("reference_files")
    fit = str(mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), 16).save(d / "fit.npz"))
    h = mf.leadr.gaussian_heightfield((16, 16), 0.3, seed=1)
    pyramid = str(mf.leadr.write_pyramid(d / "pyramid.exr", mf.leadr.bake(h)))
    slopes = np.random.default_rng(0).normal(0.0, 0.2, (8, 8, 2))
    glints = str(mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.08).save(d / "glints.npz"))
    return {"mf_fitted": fit, "mf_leadr": pyramid, "mf_glints": glints, "fit": fit}


#: Parameters given with another one (the other of a pair).
PARTNERS = {"alpha_u": {"alpha_v": 0.2}, "alpha_v": {"alpha_u": 0.2}}


def _value(param, files):
    """An accepted value of ``param``: its documented default, an example for the others."""
    if param.name == "fit":
        return files["fit"]
    d = param.default.strip("`")
    if d in ("true", "false"):
        return d == "true"
    if param.type == "integer":
        return int(d)
    try:
        return float(d)
    except ValueError:
        return d


@pytest.mark.parametrize("plugin", list(PLUGIN_CLASSES))
def test_every_documented_parameter_is_read(plugin, files):
    mi.set_variant("scalar_rgb")
    mfm.register()
    module = __import__(f"microfacet.mitsuba.{PLUGIN_CLASSES[plugin][0]}", fromlist=["bsdf_class"])
    for param in parameter_table(plugin):
        if param.name == "filename":
            continue
        props = mi.Properties(plugin)
        if plugin != "mf_microfacet":
            props["filename"] = files[plugin]
        for name, value in {param.name: _value(param, files), **PARTNERS.get(param.name, {})}.items():
            props[name] = value
        module.bsdf_class()(props)
        assert props.was_queried(param.name), f"{plugin} does not read its documented parameter {param.name!r}"
        assert not props.unqueried(), (plugin, param.name, props.unqueried())
