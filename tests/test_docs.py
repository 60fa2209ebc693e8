"""The documentation: docstring examples run (doctest), the README stays short and names the
commands CI and a newcomer need, the getting-started recipe runs, and the docs site builds
with warnings as errors (mkdocs --strict also fails on broken internal links and anchors)."""
import ast
import doctest
import importlib
import importlib.util
import inspect
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import DATA

ROOT = Path(__file__).resolve().parents[1]

#: modules whose public names must each have a runnable example (the docs helper's modules:
#: every name of their ``__all__`` and of ``microfacet.__all__`` defined in them)
OWNED_MODULES = (
    "microfacet.distributions", "microfacet.distributions.base", "microfacet.distributions.beckmann",
    "microfacet.distributions.ggx", "microfacet.distributions.tabulated", "microfacet.fresnel", "microfacet.metrics",
    "microfacet.geometry", "microfacet.diffuse", "microfacet.layered", "microfacet.layered.coat",
    "microfacet.render", "microfacet.render.compare", "microfacet.render.integrate", "microfacet.render.lights",
    "microfacet.render.lobes", "microfacet.render.sphere", "microfacet.io", "microfacet.io.atomic",
    "microfacet.io.exr", "microfacet.io.html", "microfacet.io.image", "microfacet.io.names",
    "microfacet.io.normalmap", "microfacet.io.npz", "microfacet.io.png", "microfacet.io.quiet", "microfacet.io.read",
    "microfacet.anchors", "microfacet.validation",
    # the core, fitting, measured, LEADR and batch modules
    "microfacet.brdf", "microfacet.params", "microfacet.protocol", "microfacet.backend", "microfacet.kernels",
    "microfacet.precompile", "microfacet.kernels_extra",
    "microfacet.fit", "microfacet.fit.fitted", "microfacet.fit.extract", "microfacet.fit.analytic",
    "microfacet.fit.perceptual", "microfacet.fit.outputs", "microfacet.fit.spec", "microfacet.fit.albedo",
    "microfacet.measured", "microfacet.measured.base", "microfacet.measured.grids", "microfacet.measured.marginal2d",
    "microfacet.measured.merl", "microfacet.measured.rgl", "microfacet.measured.tensor_file", "microfacet.measured.utia",
    "microfacet.leadr", "microfacet.leadr.downsample", "microfacet.leadr.figures", "microfacet.leadr.files",
    "microfacet.leadr.heightfield", "microfacet.leadr.maps", "microfacet.leadr.mip", "microfacet.leadr.moments",
    "microfacet.leadr.preview", "microfacet.leadr.shading",
    "microfacet.batch", "microfacet.batch.files", "microfacet.batch.memory", "microfacet.batch.runner",
    "microfacet.batch.tasks", "microfacet.batch.workers",
    # the Mitsuba 3 plugins (the modules that import mitsuba are skipped where it is not installed)
    "microfacet.mitsuba", "microfacet.mitsuba.registry", "microfacet.mitsuba.properties", "microfacet.mitsuba.fresnel",
    "microfacet.mitsuba.reference", "microfacet.mitsuba.bsdf", "microfacet.mitsuba.slopes", "microfacet.mitsuba.tree",
    "microfacet.mitsuba.tabulated", "microfacet.mitsuba.fitted", "microfacet.mitsuba.leadr", "microfacet.mitsuba.glints",
    "microfacet.mitsuba.demo",
    # the exports, glints and real-time modules (export.blender_addon runs inside Blender only: it imports bpy)
    "microfacet.export", "microfacet.export.analysis", "microfacet.export.blender", "microfacet.export.blender_nodes",
    "microfacet.export.comparison", "microfacet.export.consumers", "microfacet.export.glints_threejs", "microfacet.export.gltf",
    "microfacet.export.glints_export",
    "microfacet.export.leadr_textures", "microfacet.export.leadr_threejs", "microfacet.export.leadr_consumers",
    "microfacet.export.mtlx",
    "microfacet.export.mtlx_render",
    "microfacet.export.threejs", "microfacet.export.usd",
    "microfacet.glints", "microfacet.glints.microsurface", "microfacet.glints.pbrdf", "microfacet.glints.figures",
    "microfacet.glints.reference",
    "microfacet.glsl", "microfacet.glsl.sources", "microfacet.glsl.textures", "microfacet.glsl.harness",
    "microfacet.glsl.server", "microfacet.glsl.browser", "microfacet.glsl.demo",
    # the command line and the demo
    "microfacet.cli", "microfacet.demo_materials", "microfacet.demo",
)
#: the documented modules of the Mitsuba plugins, checked apart (they need the optional mitsuba package)
MITSUBA_MODULES = tuple(m for m in OWNED_MODULES if m.startswith("microfacet.mitsuba"))
#: modules whose docstring examples are run (examples that need optional packages or files
#: are marked +SKIP); packages that only re-export names are checked through their modules
DOCTEST_MODULES = tuple(m for m in OWNED_MODULES if m not in (
    "microfacet.distributions", "microfacet.render", "microfacet.io", "microfacet.fit", "microfacet.leadr",
    "microfacet.batch")) + (
    "microfacet.cli.common", "microfacet.errors", "microfacet._buffers",
)


def _import_documented(name: str):
    """The documented module ``name``; skips the test, with the reason, for a module of
    microfacet.mitsuba where the optional Mitsuba 3 (mitsuba, drjit) is not installed."""
    try:
        return importlib.import_module(name)
    except ImportError as e:
        if name in MITSUBA_MODULES and e.name in ("mitsuba", "drjit"):
            pytest.skip(f"{name} needs Mitsuba 3 (pip install -e '.[mitsuba]'): {e}")
        raise


@pytest.mark.parametrize("name", DOCTEST_MODULES)
def test_docstring_examples_run(name, tmp_path, monkeypatch, request):
    monkeypatch.chdir(tmp_path)  # examples that write files write them here
    module = _import_documented(name)
    if name in MITSUBA_MODULES and "mitsuba" in sys.modules:   # examples set scalar_rgb: the variant is global
        mi = sys.modules["mitsuba"]
        previous = mi.variant()
        request.addfinalizer(lambda: previous and mi.variant() != previous and mi.set_variant(previous))
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(module, name) if t.examples]
    assert tests, f"{name} has no docstring examples"
    for t in tests:
        runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed (output above)"


def _example_sources(module) -> str:
    """The source of every docstring example of ``module`` (functions, classes, methods and
    the module docstring), one string."""
    finder = doctest.DocTestFinder(exclude_empty=True)
    return "\n".join(ex.source for t in finder.find(module, module.__name__) for ex in t.examples)


def public_names_without_example(modules, include_top_level: bool = True) -> list[str]:
    """``module.name`` of each public name (``__all__``) of ``modules`` with no runnable
    example: a function or class whose own docstring has no ``>>>`` line, or a constant whose
    name appears in no example of the owned modules. With ``include_top_level``, the names of
    ``microfacet.__all__`` defined in those modules are checked too (submodules are skipped:
    their names are checked where they are defined)."""

    import microfacet
    mods = [importlib.import_module(m) for m in modules]
    sources = "\n".join(_example_sources(m) for m in mods)
    owned = {m.__name__ for m in mods}
    entries = [(m.__name__, n, getattr(m, n)) for m in mods for n in getattr(m, "__all__", ())]
    if include_top_level:
        entries += [("microfacet", n, getattr(microfacet, n)) for n in microfacet.__all__]
    missing = []
    for where, name, obj in entries:
        if inspect.ismodule(obj):
            continue
        if inspect.isfunction(obj) or inspect.isclass(obj):
            if include_top_level and where == "microfacet" and obj.__module__ not in owned:
                continue
            if ">>>" not in (obj.__doc__ or ""):
                missing.append(f"{where}.{name}")
        elif not re.search(rf"\b{re.escape(name)}\b", sources):
            missing.append(f"{where}.{name}")
    return sorted(set(missing))


def test_every_public_name_of_the_documented_modules_has_an_example():
    """Every public name of :data:`OWNED_MODULES` (and of ``microfacet.__all__`` defined there)
    has an example that runs (the examples run in :func:`test_docstring_examples_run`)."""
    assert public_names_without_example([m for m in OWNED_MODULES if m not in MITSUBA_MODULES]) == []


def test_every_public_name_of_the_mitsuba_modules_has_an_example():
    """As above, for the modules of the Mitsuba plugins (they need the optional mitsuba package)."""
    pytest.importorskip("mitsuba", reason="the Mitsuba plugins need the optional mitsuba package "
                                          "(pip install -e '.[mitsuba]')")
    assert public_names_without_example(MITSUBA_MODULES, include_top_level=False) == []


def test_readme_is_short_and_names_the_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 200, f"README.md has {len(lines)} lines"
    head = "\n".join(lines[:10])
    assert "make demo" in head and "make test" in head          # the two commands, at the top
    for needle in ("microfacet fit", "mf_fitted", "--to gltf", "--to mtlx", "--to usd", "Blender",
                   "microfacet bake", "microfacet glints", "microfacet view", 'pip install "microfacet[all]"'):
        assert needle in text, needle
    # every relative link of the README points at a file of the repository
    for target in re.findall(r"\]\(([^)#\s]+)\)|src=\"([^\"]+)\"", text):
        target = next(t for t in target if t)
        if "://" not in target:
            assert (ROOT / target).exists(), f"README links to a missing file: {target}"


def _blocks(page: str, lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", page, re.S | re.M)


@pytest.mark.slow
def test_getting_started_recipe_runs(tmp_path):
    """The five-line fit -> render recipe of docs/getting-started.md, run as written on a MERL
    file: `microfacet fit` then the Python block, which writes sphere.png."""
    merl = DATA / "merl" / "nickel.binary.gz"
    if not merl.is_file():
        pytest.skip(f"shared data absent: {merl}")
    page = (ROOT / "docs" / "getting-started.md").read_text(encoding="utf-8")
    section = page.split("## Fit a measured material and render it", 1)[1].split("\n## ", 1)[0]
    (command,), (code,) = _blocks(section, "sh"), _blocks(section, "python")
    assert len(code.strip().splitlines()) == 5
    (tmp_path / "nickel.binary.gz").symlink_to(merl)
    exe = Path(sys.executable).with_name("microfacet")
    args = [str(exe)] + command.split("#")[0].split()[1:]
    r = subprocess.run(args, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "sphere.png").stat().st_size > 1000


@pytest.mark.slow
def test_docs_build_strictly(tmp_path):
    """`mkdocs build --strict` (as `make docs`): no warning (unparsable docstrings, broken
    internal links or anchors, pages missing from the nav), within 60 s; the generated pages
    are there."""
    mkdocs = Path(sys.executable).with_name("mkdocs")
    if not mkdocs.exists():
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]')")
    env = dict(os.environ, DISABLE_MKDOCS_2_WARNING="true", NO_MKDOCS_2_WARNING="1")
    site = tmp_path / "site"
    tut = _tutorials()
    for script in TUTORIALS:            # as `make tutorials` before the build (cached by script hash)
        tut.run(script)
    t = time.perf_counter()
    r = subprocess.run([str(mkdocs), "build", "--strict", "--site-dir", str(site)], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=300)
    elapsed = time.perf_counter() - t
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]
    assert "WARNING" not in r.stderr, r.stderr[-4000:]
    assert elapsed < 60, f"docs build took {elapsed:.0f} s"
    cli = (site / "cli-reference.html").read_text(encoding="utf-8")
    for command in ("fit", "bake", "glints", "glints render", "view", "export", "demo", "validate"):
        assert f"microfacet {command}</code>" in cli, command
    assert 'id="microfacet.fit.fit_analytic"' in (site / "api" / "fit.html").read_text(encoding="utf-8")
    assert 'id="microfacet.brdf.MicrofacetBRDF"' in (site / "api" / "microfacet.html").read_text(encoding="utf-8")
    for md in (ROOT / "experiments" / "results").glob("*.md"):
        assert (site / "results" / md.with_suffix(".html").name).is_file(), md.name
    for script in TUTORIALS:
        page = (site / "tutorials" / f"{script.stem}.html").read_text(encoding="utf-8")
        for name in tut.run(script).images:
            assert f'src="{script.stem}/{name}"' in page and (site / "tutorials" / script.stem / name).is_file()
    # every public name of the documented modules has an entry of the API reference
    ids = {i for page in (site / "api").glob("*.html") for i in re.findall(r'id="(microfacet[\w.]*)"', page.read_text(encoding="utf-8"))}
    unlisted = []
    for name in OWNED_MODULES:
        module, top = importlib.import_module(name), ".".join(name.split(".")[:2])
        for public in module.__all__:
            if not inspect.ismodule(getattr(module, public)) and not any(
                    i.startswith(top) and i.rsplit(".", 1)[-1] == public for i in ids):
                unlisted.append(f"{name}.{public}")
    assert not unlisted, f"public names without an API reference entry: {unlisted}"
    import microfacet.mitsuba as mfm
    if hasattr(mfm, "plugin_reference"):   # the parameter tables come from the plugin docstrings
        plugins = (site / "mitsuba-plugins.html").read_text(encoding="utf-8")
        assert "plugin_reference()" in plugins
        for plugin in mfm.PLUGINS:
            assert f'id="{plugin}"' in plugins, plugin


def _tutorials():
    """docs/scripts/tutorials.py, the executor of the tutorials of examples/."""
    spec = importlib.util.spec_from_file_location("docs_tutorials", ROOT / "docs" / "scripts" / "tutorials.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


TUTORIALS = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))


def test_tutorials_are_found():
    assert len(TUTORIALS) >= 4, [p.name for p in TUTORIALS]


@pytest.mark.parametrize("script", TUTORIALS, ids=lambda p: p.stem)
def test_tutorial_runs_and_writes_its_pictures(script, tmp_path):
    """Each tutorial runs as the docs run it (its own process, an empty folder, no cache) and
    writes every picture its code names (the "*.png" literals of the script); its page has
    the title, the code and those pictures."""
    if script.stem == "05_mitsuba" and importlib.util.find_spec("mitsuba") is None:
        pytest.skip("mitsuba is not installed (pip install -e '.[mitsuba]'): 05_mitsuba renders nothing")
    tut = _tutorials()
    result = tut.run(script, force=True, folder=tmp_path / script.stem)
    named = set(re.findall(r"[\"']([\w-]+\.png)[\"']", script.read_text(encoding="utf-8")))
    assert named, f"{script.name} names no picture"
    for name in named:
        path = result.folder / name
        assert path.is_file() and path.stat().st_size > 1000, f"{script.name} did not write {name}"
    assert set(result.images) >= named
    page = tut.page(script, result, "img/")
    title = tut.split_docstring(script)[0]
    assert page.startswith(f"# {title}\n") and "```python" in page
    assert all(f"](img/{name})" in page for name in named)


def test_tutorial_cache_reruns_only_a_changed_script(tmp_path):
    """The executor keeps a script's output until the script's text changes."""
    tut = _tutorials()
    script = tmp_path / "00_tiny.py"
    script.write_text('"""Tiny\n\nWrites one picture."""\nimport microfacet as mf\nimport numpy as np\n'
                      'mf.io.write_png("tiny.png", np.random.default_rng().random((48, 48, 3)))\n'
                      'print("done")\n', encoding="utf-8")
    first = tut.run(script, folder=tmp_path / "out")
    assert first.images == ("tiny.png",) and first.output.strip() == "done"
    picture = (tmp_path / "out" / "tiny.png").read_bytes()
    assert tut.run(script, folder=tmp_path / "out").seconds == round(first.seconds, 2)   # from the stamp
    assert (tmp_path / "out" / "tiny.png").read_bytes() == picture                       # not rerun
    script.write_text(script.read_text(encoding="utf-8").replace("done", "again"), encoding="utf-8")
    assert tut.run(script, folder=tmp_path / "out").output.strip() == "again"
    script.write_text("import sys\nsys.exit(3)\n", encoding="utf-8")
    with pytest.raises(RuntimeError, match="exit 3"):
        tut.run(script, folder=tmp_path / "bad")


#: words before a year that name a venue or an organisation, not an author
_VENUES = {"EGSR", "JCGT", "Eurographics", "SIGGRAPH", "Foundation", "CGF", "TOG", "GRAPHITE", "Asia", "Issue",
           "Rendering", "Graphics", "Techniques", "Proc", "Workshop", "Python", "NumPy", "Blender", "OpenEXR"}
_CITATION = re.compile(r"\b([A-Z][\w'\-]+(?:(?:,|\s+&|\s+and)\s+[A-Z][\w'\-]+)*(?:\s+et\s+al\.)?)[\s,(]+((?:19|20)\d\d)\b")


def author_year_citations(text: str) -> set[tuple[str, str]]:
    """``(first author, year)`` of each "Author Year" / "A & B Year" / "A et al. Year" of ``text``."""
    found = set()
    for names, year in _CITATION.findall(text):
        first = re.split(r"[\s,&]+", names)[0]
        if first not in _VENUES and not first.isupper() or first in ("CIE",):
            found.add((first, year))
    return found


def test_author_year_citations_are_in_the_references():
    """Every "Author Year" cited in the docs pages, the tutorials and the docstrings of the
    documented modules has an entry "**Author ... Year**" in docs/references.md."""
    refs = (ROOT / "docs" / "references.md").read_text(encoding="utf-8")
    entries = set(re.findall(r"^- \*\*([^\s*&,]+)[^*]*?((?:19|20)\d\d)\*\*", refs, re.M))
    texts = {p.relative_to(ROOT).as_posix(): p.read_text(encoding="utf-8")
             for p in [*(ROOT / "docs").glob("*.md"), *TUTORIALS] if p.name != "references.md"}
    for name in OWNED_MODULES:
        texts[name] = Path(importlib.util.find_spec(name).origin).read_text(encoding="utf-8")   # without importing it
    missing = sorted({f"{a} {y} ({where})" for where, text in texts.items()
                      for a, y in author_year_citations(text) if (a, y) not in entries})
    assert not missing, f"cited but not in docs/references.md: {missing}"


# -- numpydoc Parameters / Returns sections --------------------------------------------------

#: numpydoc section headings: a title line underlined by dashes
_SECTION = re.compile(r"^([A-Z][A-Za-z ]*)\n-{3,}[ \t]*$", re.M)
#: the methods by which a Mitsuba 3 BSDF plugin implements Mitsuba's interface
MITSUBA_INTERFACE = frozenset({"eval", "sample", "pdf", "eval_pdf", "traverse", "parameters_changed", "to_string"})


def numpydoc_sections(doc: str) -> dict[str, str]:
    """``{title: body}`` of the numpydoc sections of a (cleaned) docstring."""
    parts = _SECTION.split(doc)
    return {parts[i]: parts[i + 1] for i in range(1, len(parts) - 1, 2)}


def documented_names(body: str) -> set[str]:
    """The names of the entries (``a, b : type`` or ``a``) of a Parameters section's body."""
    names = set()
    for line in body.splitlines():
        if line and not line[0].isspace():
            for name in line.split(" : ", 1)[0].rstrip(":").split(","):
                names.add(name.strip().lstrip("*"))
    return names


class _Returns(ast.NodeVisitor):
    """Whether a function body (not its nested functions) returns a value or yields."""
    def __init__(self):
        self.returns = self.yields = False

    def visit_Return(self, node):
        if node.value is not None and not (isinstance(node.value, ast.Constant) and node.value.value is None):
            self.returns = True

    def visit_Yield(self, node):          # a bare ``yield`` (a context manager's) yields nothing
        if node.value is not None and not (isinstance(node.value, ast.Constant) and node.value.value is None):
            self.yields = True

    def visit_YieldFrom(self, node):
        self.yields = True

    def visit_FunctionDef(self, node):   # nested definitions: not this function's returns
        pass

    visit_AsyncFunctionDef = visit_Lambda = visit_ClassDef = visit_FunctionDef


_TREES: dict = {}


def _function_node(func):
    """The ``ast`` node of ``func``'s definition (by file and first line), or None."""
    code = getattr(func, "__code__", None)
    if code is None:
        return None
    path = code.co_filename
    if path not in _TREES:
        try:
            tree = ast.parse(Path(path).read_text(encoding="utf-8"))
        except (OSError, SyntaxError):
            tree = None
        index = {}
        for node in ast.walk(tree) if tree else ():
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for line in [node.lineno, *(d.lineno for d in node.decorator_list)]:
                    index[line] = node
        _TREES[path] = index
    return _TREES[path].get(code.co_firstlineno)


def _problems(label, func, doc, skip_first=False, attributes_ok=False):
    sig_params = [p for p in inspect.signature(func).parameters.values()]
    if skip_first and sig_params:
        sig_params = sig_params[1:]
    names = [p.name for p in sig_params if p.name not in ("self", "cls")]
    sections = numpydoc_sections(inspect.cleandoc(doc or ""))
    out = []
    if names:
        documented = documented_names(sections.get("Parameters", ""))
        if attributes_ok:
            documented |= documented_names(sections.get("Attributes", ""))
        missing = [n for n in names if n not in documented]
        if "Parameters" not in sections and not (attributes_ok and "Attributes" in sections):
            out.append(f"{label}: no Parameters section")
        elif missing:
            out.append(f"{label}: Parameters lacks {', '.join(missing)}")
    node = _function_node(func)
    if node is not None:
        v = _Returns()
        for stmt in node.body:
            v.visit(stmt)
        if v.yields and "Yields" not in sections and "Returns" not in sections:
            out.append(f"{label}: no Yields section")
        elif v.returns and not v.yields and "Returns" not in sections:
            out.append(f"{label}: no Returns section")
    return out


def _plain(obj):
    """A function itself: unwraps decorators and numba dispatchers."""
    obj = getattr(obj, "py_func", obj)
    return inspect.unwrap(obj) if callable(obj) else obj


def _is_mitsuba_plugin(cls) -> bool:
    """A subclass of ``mi.BSDF``, or a plain plugin class of :mod:`microfacet.mitsuba.registry`
    (one that ``variant_class`` turns into one: its ``__init__`` starts ``mi.BSDF.__init__``)."""
    if any(b.__module__.startswith("mitsuba") and b.__name__ == "BSDF" for b in cls.__mro__):
        return True
    init = cls.__dict__.get("__init__")
    try:
        return inspect.isfunction(init) and "mi.BSDF.__init__(self" in inspect.getsource(init)
    except (OSError, TypeError):
        return False


def parameter_doc_problems(modules) -> list[str]:
    """One line per public function, class or method of ``modules`` whose docstring lacks a
    numpydoc ``Parameters`` entry for one of its parameters, or a ``Returns``/``Yields``
    section where its source returns a value (``python tests/test_docs.py`` lists them)."""
    seen, problems = set(), []
    for modname in modules:
        module = importlib.import_module(modname)
        names = getattr(module, "__all__", None) or [n for n in vars(module) if not n.startswith("_")]
        for name in names:
            obj = getattr(module, name)
            owner = getattr(obj, "__module__", None) or ""
            if not owner.startswith("microfacet") or id(obj) in seen:
                continue
            seen.add(id(obj))
            label = f"{owner}.{getattr(obj, '__qualname__', name)}"
            if inspect.isclass(obj):
                init = obj.__dict__.get("__init__")
                doc = obj.__doc__ or ""
                if init is not None and inspect.isfunction(init) and init.__doc__ and init.__module__.startswith("microfacet") :
                    doc += "\n\n" + inspect.cleandoc(init.__doc__)
                try:
                    problems += _problems(label, obj, doc, attributes_ok=True)
                except (TypeError, ValueError):    # no signature (e.g. a C base class)
                    pass
                plugin = _is_mitsuba_plugin(obj)
                for cls in obj.__mro__:
                    if not cls.__module__.startswith("microfacet"):
                        continue
                    for mname, raw in vars(cls).items():
                        if mname.startswith("_") or isinstance(raw, property) or id(raw) in seen:
                            continue
                        if plugin and mname in MITSUBA_INTERFACE and obj.__doc__:
                            continue
                        func = raw.__func__ if isinstance(raw, (staticmethod, classmethod)) else raw
                        func = _plain(func)
                        if not inspect.isfunction(func):
                            continue
                        seen.add(id(raw))
                        # an override without a docstring has its base method's (inspect.getdoc, help())
                        doc = func.__doc__ or inspect.getdoc(getattr(obj, mname))
                        problems += _problems(f"{cls.__module__}.{cls.__qualname__}.{mname}", func, doc,
                                              skip_first=isinstance(raw, classmethod))
            else:
                func = _plain(obj)
                if inspect.isfunction(func):
                    problems += _problems(label, func, func.__doc__)
    return sorted(problems)


def test_public_functions_document_their_parameters_and_returns():
    """Every public function, class and method of :data:`OWNED_MODULES` (Mitsuba's apart)
    whose signature has parameters names each in a numpydoc ``Parameters`` section, and has
    a ``Returns`` (``Yields``) section where its source returns (yields) a value."""
    problems = parameter_doc_problems([m for m in OWNED_MODULES if m not in MITSUBA_MODULES])
    assert not problems, f"{len(problems)} docstrings lack numpydoc sections:\n" + "\n".join(problems)


def test_mitsuba_plugins_document_their_parameters_and_returns():
    """As above, for the modules of the Mitsuba plugins (the BSDF interface methods of a
    documented plugin class are exempt: the class docstring documents the plugin)."""
    pytest.importorskip("mitsuba", reason="the Mitsuba plugins need the optional mitsuba package "
                                          "(pip install -e '.[mitsuba]')")
    problems = parameter_doc_problems(MITSUBA_MODULES)
    assert not problems, f"{len(problems)} docstrings lack numpydoc sections:\n" + "\n".join(problems)


if __name__ == "__main__":      # python tests/test_docs.py: the public names without an example, all modules
    import pkgutil

    import microfacet
    modules = [m.name for m in pkgutil.walk_packages(microfacet.__path__, "microfacet.")
               if not any(p.startswith("_") for p in m.name.split(".")[1:])]
    importable = []
    for name in modules:
        try:
            if hasattr(importlib.import_module(name), "__all__"):
                importable.append(name)
        except ImportError as e:
            print(f"{name}: not importable here ({e})")
    missing = public_names_without_example(importable)
    others = [m for m in missing if not m.startswith(tuple(o + "." for o in OWNED_MODULES))]
    print(f"{len(missing)} public names without an example ({len(others)} outside the documented modules; "
          "a re-exported name counts in each module that lists it)")
    for name in missing:
        print(" ", name)
    problems = parameter_doc_problems([m for m in OWNED_MODULES if m in importable])
    print(f"{len(problems)} missing numpydoc Parameters/Returns sections in the documented modules "
          f"({len({p.split(': ')[0] for p in problems})} definitions):")
    for line in problems:
        print(" ", line)
