"""The code's shape, checked the way a reviewer reads it (issue 16).

* The import graph of ``hdgym``, ``controllers`` and ``agents`` (read with
  ``ast``, every ``import`` in a file, lazy ones inside functions included)
  has no cycle, and no arrow runs from ``hdgym`` up to ``controllers`` or
  ``agents``; only ``hdgym/cli.py``, the command that composes all three, may
  name them.
* No ``.py`` file is longer than :data:`MAX_LINES` lines unless its module
  docstring has a line ``Long because: <reason>``.
* The README's layout section names only paths that exist, and names every
  module and package directly under ``hdgym/`` and the top-level packages.
* The packages above hdgym reach it through entry points (``hdgym/plugins.py``)
  that name modules which exist, and a package declaring one fills hdgym's
  registries.

Each failure names the files (and lines) that break the rule.

The file-length rule is checked by :func:`long_files`; its test joins this
file once the other splits of issue 16 are on main (today it names the files
still over the limit).
"""

from __future__ import annotations

import ast
import re
import sys
import textwrap
import tomllib
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("hdgym", "controllers", "agents")
#: the library (everything in hdgym but the CLI) must not import these
USERS = ("controllers", "agents")
COMPOSER = "hdgym/cli.py"
MAX_LINES = 500
REASON = "Long because:"


def _py_files(*tops: str) -> Iterator[Path]:
    for top in tops:
        yield from sorted((ROOT / top).rglob("*.py"))


def _module_of(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_of(f): f for f in _py_files(*PACKAGES)}


def _imports(path: Path, modules: dict[str, Path]) -> Iterator[tuple[int, str]]:
    """(line, module) for each import in ``path`` that names a module of the repository.

    ``from a.b import c`` names ``a.b.c`` when that is a module, else ``a.b``;
    relative imports are resolved against the file's package.
    """
    package = _module_of(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                name = alias.name
                while name and name not in modules:  # "import a.b.c" of a non-module c
                    name = name.rpartition(".")[0]
                if name:
                    yield node.lineno, name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package[: len(package) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}" if base else alias.name
                if full in modules:
                    yield node.lineno, full
                elif base in modules:
                    yield node.lineno, base


def import_graph() -> dict[str, dict[str, int]]:
    """``{module: {imported module: first line}}`` over the repository's packages."""
    modules = _modules()
    graph: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        edges: dict[str, int] = {}
        for line, target in _imports(path, modules):
            if target != name:
                edges.setdefault(target, line)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph) + 100))

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def _file(module: str) -> str:
    return str(_modules()[module].relative_to(ROOT))


def cycle_problems() -> list[str]:
    """Each import cycle: its files, then the import lines that tie them."""
    graph = import_graph()
    problems = []
    for comp in cycles(graph):
        members = set(comp)
        ties = [f"    {_file(a)}:{graph[a][b]} imports {b}"
                for a in comp for b in sorted(graph[a]) if b in members]
        problems.append(f"cycle of {len(comp)} files: " + ", ".join(_file(m) for m in comp)
                        + "\n" + "\n".join(ties))
    return problems


def test_import_graph_has_no_cycle() -> None:
    problems = cycle_problems()
    assert not problems, "import cycles:\n" + "\n".join(problems)


def upward_arrows() -> list[str]:
    """``file:line imports module`` for each import from hdgym (but the CLI) of its users."""
    graph = import_graph()
    composer = _module_of(ROOT / COMPOSER)
    return [f"{_file(a)}:{line} imports {b}"
            for a, edges in sorted(graph.items())
            if a.split(".")[0] == "hdgym" and a != composer
            for b, line in sorted(edges.items()) if b.split(".")[0] in USERS]


def test_hdgym_never_imports_its_users() -> None:
    arrows = upward_arrows()
    assert not arrows, ("hdgym reaches up into the packages built on it (register through "
                        "hdgym/plugins.py entry points instead):\n" + "\n".join(arrows))


def long_files() -> list[str]:
    """``path: N lines`` of each .py file over :data:`MAX_LINES` without a stated reason."""
    out = []
    for f in _py_files(*PACKAGES, "tests"):
        n = len(f.read_text().splitlines())
        if n <= MAX_LINES:
            continue
        doc = ast.get_docstring(ast.parse(f.read_text(), str(f))) or ""
        if not any(line.strip().startswith(REASON) for line in doc.splitlines()):
            out.append(f"{f.relative_to(ROOT)}: {n} lines")
    return out


def readme_layout() -> str:
    """The indented block under the README's "## Layout" heading."""
    text = (ROOT / "README.md").read_text()
    section = text.partition("\n## Layout\n")[2].split("\n## ")[0]
    return "\n".join(line for line in section.splitlines() if line.startswith("    "))


def layout_problems() -> list[str]:
    """Paths the README's layout names that do not exist, and parts of the tree it leaves out."""
    block = readme_layout()
    if not block:
        return ["README.md has no indented block under '## Layout'"]
    named = set(re.findall(r"(?<![\w/.-])((?:hdgym|controllers|agents|results|docs|tests)"
                           r"(?:/[\w.-]+)*/?)", block))
    out = [f"names {p}, which does not exist" for p in sorted(named)
           if not (ROOT / p.rstrip("/")).exists()]
    parts = [f"{top}/" for top in PACKAGES[1:]] + sorted(
        f"hdgym/{f.name}" if f.is_file() else f"hdgym/{f.name}/"
        for f in (ROOT / "hdgym").iterdir()
        if (f.suffix == ".py" and f.name != "__init__.py")
        or (f.is_dir() and not f.name.startswith(("_", "."))))
    out += [f"leaves out {p}" for p in parts if p not in named]
    return out


def test_no_long_file_without_a_reason() -> None:
    """No .py file over MAX_LINES lines unless its docstring says why (a "Long because:" line)."""
    assert not long_files(), "\n".join(long_files())


def test_readme_layout_matches_the_tree() -> None:
    problems = layout_problems()
    assert not problems, "README.md, ## Layout:\n" + "\n".join(problems)


# ------------------------------------------------------------------ the checks themselves


def test_the_checks_see_cycles_arrows_and_long_files(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The rules above can fail: a made-up tree with each fault is caught."""
    pkg = tmp_path / "hdgym"
    (pkg / "sub").mkdir(parents=True)
    (tmp_path / "controllers").mkdir()
    (tmp_path / "agents").mkdir()
    (tmp_path / "tests").mkdir()
    for d in (pkg, pkg / "sub", tmp_path / "controllers", tmp_path / "agents"):
        (d / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from hdgym.sub import b\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..a import x\n")
    (pkg / "c.py").write_text("import controllers.x.y\n")
    (pkg / "cli.py").write_text("from agents import z\n")
    (tmp_path / "controllers" / "x.py").write_text("import hdgym.c\n")
    (tmp_path / "agents" / "z.py").write_text("")
    body = "x = 1\n" * (MAX_LINES + 1)
    (pkg / "long.py").write_text('"""Long."""\n' + body)
    (pkg / "ok_long.py").write_text('"""Long.\n\nLong because: a table.\n"""\n' + body)
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)

    graph = import_graph()
    assert graph["hdgym.a"] == {"hdgym.sub.b": 1}
    assert graph["hdgym.sub.b"] == {"hdgym.a": 2}  # relative, inside a function
    assert cycles(graph) == [["controllers.x", "hdgym.c"], ["hdgym.a", "hdgym.sub.b"]]
    problems = cycle_problems()
    assert len(problems) == 2
    assert problems[1] == ("cycle of 2 files: hdgym/a.py, hdgym/sub/b.py\n"
                           "    hdgym/a.py:1 imports hdgym.sub.b\n"
                           "    hdgym/sub/b.py:2 imports hdgym.a")
    assert upward_arrows() == ["hdgym/c.py:1 imports controllers.x"]  # not cli.py: it composes
    assert long_files() == [f"hdgym/long.py: {MAX_LINES + 2} lines"]
    (tmp_path / "README.md").write_text(
        "# x\n\n## Layout\n\n    hdgym/a.py   a; hdgym/gone.py: b\n    hdgym/sub/\n\n## Next\n")
    problems = layout_problems()
    assert "names hdgym/gone.py, which does not exist" in problems
    assert "leaves out hdgym/c.py" in problems and "leaves out controllers/" in problems
    assert "leaves out hdgym/a.py" not in problems and "leaves out hdgym/sub/" not in problems


# ------------------------------------------------------------------ entry points


def test_pyproject_entry_points_name_modules_that_exist() -> None:
    from hdgym import plugins

    eps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    declared = {g: eps.get(g, {}) for g in (plugins.SWEEP_SCENARIOS, plugins.BENCH_SECTIONS)}
    assert declared[plugins.SWEEP_SCENARIOS] == {"controllers": "controllers.sweep",
                                                 "agents": "agents.sweep"}
    assert declared[plugins.BENCH_SECTIONS] == {"agents": "agents.bench"}
    modules = _modules()
    for group in declared.values():
        for value in group.values():
            assert value.partition(":")[0] in modules, value


def test_entry_points_fill_the_registries(tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A package that declares the entry points gets its scenario and bench section
    registered; one that cannot be imported is named, not fatal."""
    from hdgym import bench, plugins
    from hdgym.sweep import scenarios

    (tmp_path / "structure_plugin_mod.py").write_text(textwrap.dedent("""\
        from hdgym.bench import register_section
        from hdgym.sweep.scenarios import register

        @register("structure_plugin_scenario", options={})
        def run(params, job):
            return {"x": 1.0}

        @register_section("Structure plugin section", order=35)
        def rows(quick):
            return [{"name": "one", "value": 1.0}]
        """))
    dist = tmp_path / "structure_plugin-0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: structure-plugin\nVersion: 0\n")
    (dist / "entry_points.txt").write_text(
        f"[{plugins.SWEEP_SCENARIOS}]\nok = structure_plugin_mod\nbroken = no_such_module_x\n\n"
        f"[{plugins.BENCH_SECTIONS}]\nok = structure_plugin_mod\n")
    scenarios.scenario_names(), bench.sections()  # the installed ones, before the copies
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(scenarios, "_REGISTRY", dict(scenarios._REGISTRY))
    monkeypatch.setattr(bench, "_SECTIONS", dict(bench._SECTIONS))
    monkeypatch.delitem(sys.modules, "structure_plugin_mod", raising=False)

    assert "structure_plugin_scenario" in scenarios.scenario_names()
    assert scenarios.get_scenario("structure_plugin_scenario").fn(None, None) == {"x": 1.0}
    with pytest.raises(ValueError, match=r"unknown scenario 'nope'; entry point 'broken': "
                                         r"cannot import no_such_module_x"):
        scenarios.get_scenario("nope")
    found, failed = bench.sections()
    titles = [s.title for s in found]
    assert "Structure plugin section" in titles
    assert titles.index("Gymnasium environments") < titles.index("Structure plugin section")
    assert titles.index("Structure plugin section") < titles.index("Discrepancy workflow")
    assert "broken" not in failed  # only in the sweep group
    sys.modules.pop("structure_plugin_mod", None)
