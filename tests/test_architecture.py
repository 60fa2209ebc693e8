"""Architecture checks on the source of ``src/microfacet`` (read with :mod:`ast`, nothing
is imported): no circle among module-level imports, no import of another module's private
(``_underscore``) names, and a report of the longest functions and of those taking many
parameters.

Run as a script for the report::

    python tests/test_architecture.py          # cycles, private imports, long functions

Definitions used here:

* an import is *module-level* when it runs on ``import`` of the module: anywhere outside
  a ``def``/``lambda`` body (class bodies, ``if``/``try`` blocks included), except under
  ``if TYPE_CHECKING:`` (never run); an import inside a function is *function-level*
  (deferred) and is reported separately; imports under ``if __name__ == "__main__":`` run
  only when the module is run as a script (``python -m``), as a module of its own
  (``__main__``), and are no edges;
* ``from pkg.a import b`` is an edge to ``pkg.a.b`` when ``b`` is a submodule, else to
  ``pkg.a``; importing a module's ancestors (``pkg/__init__``) is not an edge, since a
  package's ``__init__`` is already running when its submodules are imported;
* a name is *private* when it starts with one underscore (not a dunder); importing
  ``from m import _x``, or reading ``m._x`` on an imported module ``m``, is a private
  import unless ``m`` is the importing module itself. Private *modules*
  (``microfacet._numba_kernels``) may be imported by their own package, which owns them.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "microfacet"

#: Files owned by the project lead (issue 27): their private imports are listed here until
#: the lead replaces them with public names; this allow-list is meant to be emptied.
LEAD_OWNED = frozenset({
})


def module_files() -> dict[str, Path]:
    """Dotted module name -> source file, for every ``.py`` under ``src/microfacet``."""
    out = {}
    for path in sorted((SRC / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    """Absolute module named by a (possibly relative) import inside ``module``."""
    if level == 0:
        return name or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _is_main(test: ast.expr) -> bool:
    """``__name__ == "__main__"``: the block runs when the module is run as a script only."""
    return isinstance(test, ast.Compare) and isinstance(test.left, ast.Name) and test.left.id == "__name__" \
        and len(test.comparators) == 1 and isinstance(test.comparators[0], ast.Constant) \
        and test.comparators[0].value == "__main__"


class _Imports(ast.NodeVisitor):
    """Collect (target module, imported name or None, line, deferred?) of one file."""

    def __init__(self, module: str, is_package: bool, modules: set[str]):
        self.module, self.is_package, self.modules = module, is_package, modules
        self.depth = 0
        self.found: list[tuple[str, str | None, int, bool]] = []
        self.aliases: dict[str, str] = {}  # local name -> module it is bound to

    def _scope(self, node):
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = visit_Lambda = _scope

    def visit_If(self, node: ast.If):
        if _is_type_checking(node.test):
            for child in node.orelse:
                self.visit(child)
            return
        if _is_main(node.test):                 # runs as a script only (``python -m``): no import edge
            for child in node.orelse:
                self.visit(child)
            return
        self.generic_visit(node)

    def visit_Import(self, node: ast.Import):
        for alias in node.names:
            if alias.name.split(".")[0] == PACKAGE:
                self.found.append((alias.name, None, node.lineno, self.depth > 0))
                self.aliases[alias.asname or alias.name] = alias.name

    def visit_ImportFrom(self, node: ast.ImportFrom):
        target = _resolve(self.module, self.is_package, node.level, node.module)
        if target.split(".")[0] != PACKAGE:
            return
        for alias in node.names:
            sub = f"{target}.{alias.name}"
            if sub in self.modules:
                self.found.append((sub, None, node.lineno, self.depth > 0))
                self.aliases[alias.asname or alias.name] = sub
            else:
                self.found.append((target, alias.name, node.lineno, self.depth > 0))


def imports(files: dict[str, Path] | None = None):
    """Per module: list of (target module, name or None, line, deferred?)."""
    files = files or module_files()
    names = set(files)
    out = {}
    for module, path in files.items():
        tree = ast.parse(path.read_text(), str(path))
        v = _Imports(module, path.name == "__init__.py", names)
        v.visit(tree)
        # attribute reads ``alias._name`` on an imported module
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                    and node.value.id in v.aliases:
                v.found.append((v.aliases[node.value.id], node.attr, node.lineno, None))
        out[module] = v.found
    return out


def import_graph(module_level: bool = True) -> dict[str, set[str]]:
    """Edges module -> imported module (module-level or function-level imports only)."""
    files = module_files()
    graph: dict[str, set[str]] = {m: set() for m in files}
    for module, found in imports(files).items():
        for target, _name, _line, deferred in found:
            if deferred is None or deferred == module_level:
                continue
            if target in files and target != module and not module.startswith(target + "."):
                graph[module].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))

    def visit(v: str):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def _private(name: str | None) -> bool:
    return bool(name) and name.startswith("_") and not name.startswith("__")


def private_imports() -> list[tuple[str, int, str, str]]:
    """(importing module, line, target module, private name) for every import of another
    module's private name (``from m import _x`` or ``m._x``)."""
    out = []
    for module, found in imports().items():
        for target, name, line, _deferred in found:
            if _private(name) and target != module:
                out.append((module, line, target, name))
    return sorted(set(out))


def functions(min_lines: int = 0, min_params: int = 0):
    """(qualified name, file:line, lines, parameters) of every function definition
    with at least ``min_lines`` lines or at least ``min_params`` parameters."""
    out = []
    for module, path in module_files().items():
        tree = ast.parse(path.read_text(), str(path))
        stack: list[tuple[ast.AST, str]] = [(tree, module)]
        while stack:
            node, prefix = stack.pop()
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    qual = f"{prefix}.{child.name}"
                    if not isinstance(child, ast.ClassDef):
                        a = child.args
                        n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) \
                            + (a.vararg is not None) + (a.kwarg is not None)
                        if a.args and a.args[0].arg in ("self", "cls"):
                            n -= 1
                        lines = child.end_lineno - child.lineno + 1
                        if (min_lines and lines >= min_lines) or (min_params and n >= min_params):
                            out.append((qual, f"{path.relative_to(SRC.parent)}:{child.lineno}", lines, n))
                    stack.append((child, qual))
                else:
                    stack.append((child, prefix))
    return out


# -- tests -------------------------------------------------------------------------------

def test_graph_sees_the_package():
    graph = import_graph()
    assert "microfacet.brdf" in graph and "microfacet.kernels" in graph["microfacet.brdf"]


def test_cycle_finder_finds_a_planted_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_level_import_cycle():
    found = cycles(import_graph(module_level=True))
    assert not found, "module-level import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_no_cycle_through_deferred_imports_either():
    """Imports inside functions (Numba, Mitsuba: optional heavy dependencies loaded on first
    use) do not close a circle either: the layers stay in one order."""
    graph = import_graph(module_level=True)
    for m, targets in import_graph(module_level=False).items():
        graph[m] = graph[m] | targets
    found = cycles(graph)
    assert not found, "import cycles through deferred imports: " + "; ".join(" <-> ".join(c) for c in found)


def test_no_private_imports_across_modules():
    bad = [p for p in private_imports() if p[0] not in LEAD_OWNED]
    assert not bad, "private names imported from another module:\n" + "\n".join(
        f"  {m}:{line} uses {t}.{n}" for m, line, t, n in bad)


#: The longest a function may be, in lines of code (a screen; its docstring not counted).
MAX_FUNCTION_LINES = 80


def code_lines(node: ast.AST) -> int:
    """Lines from ``def`` to the function's last line, less its docstring's (a public
    function's numpydoc sections document it; they do not make it harder to read)."""
    lines = node.end_lineno - node.lineno + 1
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        lines -= first.end_lineno - first.lineno + 1
    return lines


def long_functions(limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """``(file:line name, code lines)`` of every function of ``src/microfacet`` (methods and
    nested functions included) with more than ``limit`` lines of code (:func:`code_lines`)."""
    out = []
    for module, path in module_files().items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and code_lines(node) > limit:
                out.append((f"{path.relative_to(SRC.parent)}:{node.lineno} {node.name}", code_lines(node)))
    return out


def test_function_length():
    """Every function of the package fits on a screen: at most ``MAX_FUNCTION_LINES`` lines of
    code (issue 27)."""
    planted = ast.parse("def f():\n    'doc'\n" + "    x = 1\n" * 3).body[0]
    assert code_lines(planted) == 4
    long = long_functions()
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines of code:\n" + "\n".join(
        f"  {n:4d} lines  {where}" for where, n in sorted(long, key=lambda f: -f[1]))


def report() -> str:
    lines = []
    mod = cycles(import_graph(module_level=True))
    lines.append(f"module-level import cycles: {len(mod)}")
    lines += ["  " + " <-> ".join(c) for c in mod]
    both = import_graph(module_level=True)
    for m, targets in import_graph(module_level=False).items():
        both[m] = both[m] | targets
    allc = cycles(both)
    lines.append(f"cycles when function-level (deferred) imports are counted too: {len(allc)}")
    lines += ["  " + " <-> ".join(c) for c in allc]
    priv = private_imports()
    lines.append(f"private imports across modules: {len(priv)}")
    lines += [f"  {m}:{ln} -> {t}.{n}" + ("  [lead-owned]" if m in LEAD_OWNED else "")
              for m, ln, t, n in priv]
    long = sorted(long_functions(), key=lambda f: -f[1])
    lines.append(f"functions over {MAX_FUNCTION_LINES} lines of code: {len(long)}")
    lines += [f"  {n:4d} lines  {where}" for where, n in long]
    many = sorted(functions(min_params=9), key=lambda f: -f[3])
    lines.append(f"functions with more than 8 parameters: {len(many)}")
    lines += [f"  {n:3d} params {q}  ({where})" for q, where, _, n in many]
    return "\n".join(lines)


if __name__ == "__main__":
    print(report())


# -- parameters ------------------------------------------------------------------------------

#: The most parameters a function of ``src/microfacet`` takes (issue 27: records, not loose
#: argument lists; the compiled kernels take ~6, e.g. ``kernel(start, stop, p, wi, wo, out)``).
MAX_PARAMETERS = 8
#: Mitsuba fixes the signatures of these plugin methods (``mi.BSDF``'s interface), not we.
MITSUBA_FIXED = frozenset({"__init__", "sample", "eval", "pdf", "eval_pdf", "eval_pdf_sample",
                           "eval_attribute", "eval_attribute_1", "eval_attribute_3", "traverse",
                           "parameters_changed", "to_string", "eval_diffuse_reflectance"})
#: Functions allowed more than :data:`MAX_PARAMETERS` parameters, each with its reason. None is a
#: compiled kernel: they are public entry points whose options every caller passes by keyword,
#: in files of other owners (issue 27), which may make them keyword-only (``*``) and drop them here.
MANY_PARAMETERS_ALLOWED = {
    "microfacet.anchors.SGD.__init__": "public constructor of the SGD anchor: its published fit's "
                                       "parameters, by keyword (anchors.py)",
    "microfacet.batch.runner.run": "the batch command's entry point: one parameter per CLI option",
    "microfacet.batch.tasks.bake_file": "a batch task: one parameter per `microfacet bake` option",
    "microfacet.batch.tasks.fit_file": "a batch task: one parameter per `microfacet fit` option",
    "microfacet.demo.run_demo": "the demo's entry point: one parameter per `microfacet demo` option",
    "microfacet.demo._render_demo": "the demo's render step, called once by run_demo with its options",
    "microfacet.fit.analytic._Problem.__init__": "the fit's problem set-up, built once per fit from "
                                                 "fit_analytic's options (fit/, the lead's files)",
    "microfacet.fit.outputs.fit_material": "a fit of one corpus material: one parameter per "
                                           "experiment option (fit/, the lead's files)",
}


def parameter_count(args: ast.arguments, method: bool) -> int:
    """Parameters a caller may have to pass: positional ones (``self``/``cls`` of a method not
    counted), ``*args``, ``**kwargs`` and keyword-only ones without a default. Keyword-only
    parameters with a default are named options (NumPy's style: ``f(x, *, out=None)``), never
    passed positionally, and are not counted; Numba kernels have none."""
    n = len(args.posonlyargs) + len(args.args) + (args.vararg is not None) + (args.kwarg is not None) \
        + sum(d is None for d in args.kw_defaults)
    first = (args.posonlyargs + args.args)[:1]
    return n - (method and bool(first) and first[0].arg in ("self", "cls"))


def many_parameters(limit: int = MAX_PARAMETERS) -> list[tuple[str, str, int]]:
    """``(qualified name, file:line, parameters)`` of the functions of ``src/microfacet`` (nested
    ones and methods included) with more than ``limit`` parameters (:func:`parameter_count`),
    but the Mitsuba plugin methods of :data:`MITSUBA_FIXED`."""
    out = []
    for module, path in module_files().items():
        tree = ast.parse(path.read_text(), str(path))
        stack: list[tuple[ast.AST, str, bool]] = [(tree, module, False)]
        while stack:
            node, prefix, in_class = stack.pop()
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.ClassDef):
                    stack.append((child, f"{prefix}.{child.name}", True))
                elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    qual = f"{prefix}.{child.name}"
                    n = parameter_count(child.args, in_class)
                    fixed = in_class and module.startswith("microfacet.mitsuba.") and child.name in MITSUBA_FIXED
                    if n > limit and not fixed:
                        out.append((qual, f"{path.relative_to(SRC.parent)}:{child.lineno}", n))
                    stack.append((child, qual, False))
                else:
                    stack.append((child, prefix, in_class))
    return sorted(out)


def test_parameter_count_of_a_planted_function():
    """The count: positional parameters, ``*args``, ``**kwargs`` and keyword-only ones without a
    default; not ``self``, not keyword-only options with a default."""
    f = ast.parse("def f(self, a, b=1, *c, d, e=2, **g): pass").body[0]
    assert parameter_count(f.args, method=True) == 5 and parameter_count(f.args, method=False) == 6
    kernel = ast.parse("def loops(start, stop, out, E, bounds, B, nx, ny, ks2x, ks2y): pass").body[0]
    assert parameter_count(kernel.args, method=False) == 10 > MAX_PARAMETERS


def test_kernel_arguments():
    """No function of ``src/microfacet`` takes more than :data:`MAX_PARAMETERS` parameters (the
    compiled kernels take records: :class:`microfacet.params.SmithParams`,
    :class:`microfacet.glints.pbrdf.LobeGrid`, :class:`microfacet.measured.rgl.RGLTables` ...), but
    the Mitsuba plugin methods whose signatures Mitsuba fixes and the justified exceptions of
    :data:`MANY_PARAMETERS_ALLOWED` (which must still exist and still need it: the list only shrinks)."""
    found = many_parameters()
    bad = [(q, where, n) for q, where, n in found if q not in MANY_PARAMETERS_ALLOWED]
    assert not bad, f"functions with more than {MAX_PARAMETERS} parameters (pass a record):\n" + "\n".join(
        f"  {n:3d} params  {q}  ({where})" for q, where, n in sorted(bad, key=lambda f: -f[2]))
    stale = sorted(set(MANY_PARAMETERS_ALLOWED) - {q for q, _, _ in found})
    assert not stale, "MANY_PARAMETERS_ALLOWED lists functions that no longer need it: " + ", ".join(stale)
    assert all(MANY_PARAMETERS_ALLOWED.values())
