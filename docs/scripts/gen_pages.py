"""Pages generated at docs-build time (mkdocs-gen-files).

* ``cli-reference.md``: every ``microfacet`` command and subcommand, walked from the argparse
  parser of :func:`microfacet.cli.build_parser` (usage, description, one table row per
  argument), so the reference is the parser itself.
* ``results/*.md``: the Markdown that the experiments and benchmarks write
  (``experiments/results/*.md``, ``benchmarks/results/*.md``), included as written, with the
  pictures they link to; ``results/index.md`` lists them with the command that regenerates each.
* ``changelog.md``: ``CHANGELOG.md``.
* ``tutorials/*.md``: the executed tutorials of ``examples/`` (``docs/scripts/tutorials.py``:
  each script run in its own process, cached by script hash), code, output and pictures.
* ``mitsuba-plugins.md``: the hand-written page with its parameter-reference block replaced by
  :func:`microfacet.mitsuba.plugin_reference` (the tables of the plugin classes' docstrings)
  where that function exists.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import re
import sys
from pathlib import Path

import mkdocs_gen_files

ROOT = Path(__file__).resolve().parents[2]
os.environ["COLUMNS"] = "100"  # argparse wraps help at the terminal width: fix it

# -- CLI reference --------------------------------------------------------------------------


def _subparsers(parser: argparse.ArgumentParser):
    """``[(name, subparser, help)]`` of the parser's subcommands, in definition order."""
    out = []
    for action in parser._actions:  # argparse keeps no public list of its actions
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                out.append((name, sub, helps.get(name) or ""))
    return out


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _argument_rows(parser: argparse.ArgumentParser) -> list[str]:
    rows = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.help == argparse.SUPPRESS:
            continue
        names = ", ".join(f"`{s}`" for s in action.option_strings) or f"`{action.metavar or action.dest}`"
        if action.option_strings and action.nargs != 0:
            names += f" `{action.metavar or action.dest.upper()}`"
        choices = ", ".join(f"`{c}`" for c in action.choices) if action.choices else ""
        default = action.default
        shown = "" if default in (None, False, argparse.SUPPRESS) or not action.option_strings else f"`{default}`"
        help_text = (action.help or "") % {"default": default, "prog": parser.prog} if action.help else ""
        rows.append(f"| {names} | {_cell(help_text)} | {choices} | {shown} |")
    return rows


def _command(parser: argparse.ArgumentParser, name: str, summary: str, depth: int) -> list[str]:
    lines = [f"{'#' * depth} `{name}`", ""]
    if summary:
        lines += [_cell(summary), ""]
    lines += ["```text", parser.format_usage().strip(), "```", ""]
    if parser.description:
        lines += [parser.description.strip(), ""]
    rows = _argument_rows(parser)
    if rows:
        lines += ["| argument | meaning | choices | default |", "|---|---|---|---|", *rows, ""]
    if parser.epilog:
        lines += ["```text", parser.epilog.strip(), "```", ""]
    for sub_name, sub, sub_help in _subparsers(parser):
        lines += _command(sub, f"{name} {sub_name}", sub_help, min(depth + 1, 4))
    return lines


def cli_reference() -> str:
    from microfacet.cli import build_parser

    parser = build_parser()
    lines = ["# Command-line reference", "",
             "Generated from the `argparse` parsers of `microfacet.cli` when the docs are built: "
             "every command, its usage line and its arguments. The rules that every command "
             "follows (output naming, batches, faults) are in [Command-line conventions](cli.md).", ""]
    lines += _command(parser, parser.prog, "", 2)
    # `microfacet glints render ...` is a second parser that `main` dispatches to
    from microfacet.cli import glints
    for name, sub, sub_help in _subparsers(glints.render_parser()):
        lines += _command(sub, f"{parser.prog} glints {name}", sub_help, 3)
    return "\n".join(lines) + "\n"


# -- results pages --------------------------------------------------------------------------

#: results file stem -> (title when the file has none, the command that writes it)
RESULTS = {
    "table_4_1": ("Table 4.I: power-iteration fits of analytic NDFs", "python experiments/table_4_1.py --resolution 360 --out experiments/results/table_4_1.md"),
    "fit_corpus": ("Fit corpus", "python experiments/fit_corpus.py"),
    "fit_measured": ("Fits of the measured materials", "python experiments/fit_measured.py --data DATA --anisotropic"),
    "fit_energy": ("Energy of the tabulated fits", "python experiments/fit_energy.py --data DATA --resolution 90 --weights 0,2,4,8 --out experiments/results/fit_energy.md"),
    "fit_moments": ("Moment conversions and their Fresnel tables", "python experiments/fit_moments.py --data DATA"),
    "leadr_validation": ("LEADR validation", "python experiments/leadr_validation.py"),
    "glints_pndf_validation": ("Glints P-NDF validation", "python experiments/glints_pndf_validation.py"),
    "glints_threejs": ("Glints in three.js", "python experiments/glints_threejs.py"),
    "leadr_engines": ("LEADR textures in three.js", "python experiments/leadr_engines.py"),
    "leadr_consumers": ("LEADR in Blender and MaterialX", "python experiments/leadr_consumers.py"),
    "albedo_band": ("Albedo within 5 % of the data", "python experiments/albedo_band.py --data DATA"),
    "albedo_schlick": ("Albedo match: Schlick forms vs the table", "python experiments/albedo_schlick.py"),
    "albedo_bases": ("Albedo match with the bases scaled", "python experiments/albedo_bases.py --base SRC"),
    "sheared_chi2": ("Sheared lobes at grazing views: chi-square", "python experiments/sheared_chi2.py"),
    "glsl_gpu": ("GLSL shaders on an NVIDIA GPU", "python experiments/glsl_gpu.py"),
    "cold_start": ("Cold start", "python benchmarks/bench_cold_start.py"),
    "fit_command": ("The fit command's time", "python benchmarks/bench_fit_command.py --baseline SRC"),
}
RESULT_DIRS = (ROOT / "experiments" / "results", ROOT / "benchmarks" / "results")
LINK = re.compile(r"\]\(([^)#\s]+)\)")


def results_pages() -> list[tuple[str, str]]:
    """Write one page per results file (its text as written) and copy the files it links to."""
    listed = []
    for folder in RESULT_DIRS:
        for md in sorted(folder.glob("*.md")):
            text = md.read_text(encoding="utf-8")
            title, command = RESULTS.get(md.stem, (md.stem.replace("_", " ").capitalize(), ""))
            source = md.relative_to(ROOT).as_posix()
            header = [] if text.lstrip().startswith("# ") else [f"# {title}", ""]
            note = ["!!! note \"Generated\"",
                    f"    This page is `{source}` as the script wrote it"
                    + (f" (`{command}`)." if command else "."), ""]
            body = text.splitlines()
            if header:
                page = header + note + body
            else:  # keep the file's own title first
                page = body[:1] + [""] + note + body[1:]
            with mkdocs_gen_files.open(f"results/{md.name}", "w") as f:
                f.write("\n".join(page) + "\n")
            for target in LINK.findall(text):
                if "://" in target:
                    continue
                path = (md.parent / target)
                if path.is_file():
                    with mkdocs_gen_files.open(f"results/{target}", "wb") as f:
                        f.write(path.read_bytes())
            first = next((l[2:] for l in body if l.startswith("# ")), title)
            listed.append((md.name, first, command))
    return listed


def results_index(listed) -> str:
    lines = ["# Results", "",
             "The experiments (`experiments/*.py`) and benchmarks (`benchmarks/*.py`) write their "
             "figures as Markdown into `experiments/results/` and `benchmarks/results/`; these pages "
             "include those files as written when the docs are built (rerun the command, rebuild "
             "the docs). Each file states its date or machine where the script records them.", "",
             "| page | regenerated by |", "|---|---|"]
    for name, title, command in listed:
        lines.append(f"| [{_cell(title)}]({name}) | {'`' + command + '`' if command else ''} |")
    return "\n".join(lines) + "\n"


# -- tutorials --------------------------------------------------------------------------------


def _tutorials_module():
    spec = importlib.util.spec_from_file_location("docs_tutorials", Path(__file__).with_name("tutorials.py"))
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def tutorial_pages() -> None:
    """Run the stale tutorials and write ``tutorials/<stem>.md`` with their pictures."""
    tut = _tutorials_module()
    entries = []
    for script in tut.scripts():
        result = tut.run(script)
        with mkdocs_gen_files.open(f"tutorials/{script.stem}.md", "w") as f:
            f.write(tut.page(script, result, f"{script.stem}/"))
        for name in result.images:
            with mkdocs_gen_files.open(f"tutorials/{script.stem}/{name}", "wb") as f:
                f.write((result.folder / name).read_bytes())
        title, intro, _ = tut.split_docstring(script)
        entries.append((f"{script.stem}.md", title, _cell(intro.split(". ")[0].rstrip(".") + ".")))
    with mkdocs_gen_files.open("tutorials/index.md", "w") as f:
        f.write(tut.index(entries))


# -- Mitsuba plugin reference -----------------------------------------------------------------

PLUGIN_BLOCK = re.compile(r"<!-- plugin-reference:start.*?-->.*?<!-- plugin-reference:end -->", re.S)


def mitsuba_plugins_page() -> str | None:
    """``mitsuba-plugins.md`` with its parameter-reference block made of
    ``microfacet.mitsuba.plugin_reference()`` (headings one level down), or None where the
    function does not exist (the hand-written tables stay)."""
    import microfacet.mitsuba as mfm
    if not hasattr(mfm, "plugin_reference"):
        return None
    text = (ROOT / "docs" / "mitsuba-plugins.md").read_text(encoding="utf-8")
    if not PLUGIN_BLOCK.search(text):
        raise ValueError("docs/mitsuba-plugins.md: the plugin-reference markers are missing")
    generated = re.sub(r"^(#+) ", r"#\1 ", mfm.plugin_reference().strip(), flags=re.M)
    block = ("Generated from the docstrings of the plugin classes when the docs are built "
             "(`microfacet.mitsuba.plugin_reference()`, as Mitsuba generates its own plugin "
             "reference from its sources).\n\n" + generated)
    return PLUGIN_BLOCK.sub(lambda m: block, text)


with mkdocs_gen_files.open("cli-reference.md", "w") as f:
    f.write(cli_reference())
with mkdocs_gen_files.open("results/index.md", "w") as f:
    f.write(results_index(results_pages()))
with mkdocs_gen_files.open("changelog.md", "w") as f:
    f.write((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))
tutorial_pages()
_plugins = mitsuba_plugins_page()
if _plugins is not None:
    with mkdocs_gen_files.open("mitsuba-plugins.md", "w") as f:
        f.write(_plugins)
