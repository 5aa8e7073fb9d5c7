"""The house's plan, read from the code: the import graph of `tacgen_lib` has no circle and no
arrow from a lower floor up to a higher one, and no module of tacgen_lib/, workflow/ or tools/
is over MAX_LINES lines (docs/layout.md, "Floors").

The graph is read with `ast` from every module's source: every `import` and `from ... import`,
at module level, inside a function, or under `if TYPE_CHECKING:` (an annotation-only import is
still an arrow a reader follows). `from package import name` is an arrow to the module
`package.name` where that is a module, else to `package`; `import a.b.c` is an arrow to `a.b.c`
(the parent packages' `__init__` that Python runs on the way are not counted: none of them
imports anything).

Floors (`FLOORS`): each package stands on one floor; an import between two packages goes
strictly down (within one package anything goes, its circles being caught by the circle test):

0. the ground, which imports no other package of tacgen_lib: `io` (edges, hashed files, logs,
   config), `runtime` (the job runtime: the preloaded interpreter, the scheduler patch, device,
   workers, benchmark files) and `optim` (the optimiser);
1. the data: `corpus`, `preprocess`; `report_pages` (the page names the DAG reads at parse
   time);
2. the measurements: `probes`, `align`;
3. what reads probes: `language`;
4. `features`;
5. the stages built on features and heads: `generate`, `policy`;
6. what reads every stage's settings or edges: `cost` (the cost of accuracy), `estimate` (the
   run-time estimate);
7. `report` (the pages) and `workflow_config` (the config as the Snakefile checks it: the
   schema, then the corpus key rules and cross-references);
8. the roof: `plan` (what the rules expand, ask for and name; only rules/*.smk import it).

The rules hold rules, not a second program: all `.smk` files together define at most
`MAX_SMK_FUNCTIONS` functions, none over `MAX_SMK_FUNCTION_LINES` lines (`tacgen_lib.plan`
holds the rest).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "tacgen_lib"
MAX_LINES = 450
MAX_SMK_FUNCTIONS = 10
MAX_SMK_FUNCTION_LINES = 10

#: package (or top-level module) -> its floor (the longest prefix of a module's name that is a key
#: wins)
FLOORS: dict[str, int] = {
    "tacgen_lib": 0,  # the package's own __init__ (its version)
    "tacgen_lib.io": 0,
    "tacgen_lib.runtime": 0,
    "tacgen_lib.optim": 0,
    "tacgen_lib.corpus": 1,
    "tacgen_lib.preprocess": 1,
    "tacgen_lib.report_pages": 1,
    "tacgen_lib.probes": 2,
    "tacgen_lib.align": 2,
    "tacgen_lib.language": 3,
    "tacgen_lib.features": 4,
    "tacgen_lib.generate": 5,
    "tacgen_lib.policy": 5,
    "tacgen_lib.cost": 6,
    "tacgen_lib.estimate": 6,
    "tacgen_lib.report": 7,
    "tacgen_lib.workflow_config": 7,
    "tacgen_lib.plan": 8,
}


def modules(root: Path = ROOT) -> dict[str, Path]:
    """Dotted name -> source file of every module of tacgen_lib (a package by its __init__)."""
    out = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def _longest_module(name: str, mods: dict[str, Path]) -> str | None:
    """`name` if it is a module of tacgen_lib, else its longest prefix that is; None outside."""
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def _imports(tree: ast.AST, name: str, is_package: bool, mods: dict[str, Path]):
    """(module of tacgen_lib, line) of every import in a module's tree, relative ones resolved."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield _longest_module(alias.name, mods), node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = name.split(".") if is_package else name.split(".")[:-1]
                parts = parts[: len(parts) - node.level + 1]
                base = ".".join([*parts, *([node.module] if node.module else [])])
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                target = submodule if submodule in mods else _longest_module(base, mods)
                yield target, node.lineno


def import_graph(root: Path = ROOT) -> dict[str, dict[str, int]]:
    """Module -> {module of tacgen_lib it imports: the line of its first import}."""
    mods = modules(root)
    graph: dict[str, dict[str, int]] = {}
    for name, path in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        targets: dict[str, int] = {}
        for target, line in sorted(
            _imports(tree, name, path.name == "__init__.py", mods), key=lambda t: t[1]
        ):
            if target is not None and target != name:
                targets.setdefault(target, line)
        graph[name] = targets
    return graph


def circles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

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
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def room(module: str) -> str:
    """The key of `FLOORS` a module stands under: the longest one that is a prefix of it."""
    keys = [k for k in FLOORS if module == k or module.startswith(k + ".")]
    if not keys:
        raise KeyError(f"{module}: on no floor; add its package to FLOORS in {__name__}")
    return max(keys, key=len)


def package_of(module: str) -> str:
    return ".".join(module.split(".")[:2])


def upward_arrows(graph: dict[str, dict[str, int]]) -> list[str]:
    """Every import between two packages that does not go strictly down a floor."""
    bad = []
    for source, targets in sorted(graph.items()):
        for target, line in sorted(targets.items()):
            if package_of(source) == package_of(target):
                continue
            a, b = FLOORS[room(source)], FLOORS[room(target)]
            if b >= a:
                bad.append(f"{source} (floor {a}) line {line} imports {target} (floor {b})")
    return bad


GRAPH = import_graph()


def test_the_graph_sees_every_kind_of_import(tmp_path):
    """Function-level, TYPE_CHECKING, relative and `from package import module` imports."""
    pkg = tmp_path / PACKAGE / "a"
    pkg.mkdir(parents=True)
    (tmp_path / PACKAGE / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "one.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from tacgen_lib.a.two import X\n"
    )
    (pkg / "two.py").write_text("def f():\n    from . import three\n")
    (pkg / "three.py").write_text("from tacgen_lib.a import one\nimport tacgen_lib.a.four\n")
    (pkg / "four.py").write_text("import numpy\n")
    graph = import_graph(tmp_path)
    assert graph["tacgen_lib.a.one"] == {"tacgen_lib.a.two": 3}
    assert graph["tacgen_lib.a.two"] == {"tacgen_lib.a.three": 2}
    assert graph["tacgen_lib.a.three"] == {"tacgen_lib.a.one": 1, "tacgen_lib.a.four": 2}
    assert graph["tacgen_lib.a.four"] == {}
    assert circles(graph) == [["tacgen_lib.a.one", "tacgen_lib.a.three", "tacgen_lib.a.two"]]


def test_no_import_circle():
    assert circles(GRAPH) == [], "modules that import each other, however indirectly"


def test_every_module_stands_on_a_floor():
    for module in GRAPH:
        room(module)


def test_no_import_from_a_lower_floor_up():
    bad = upward_arrows(GRAPH)
    assert not bad, "imports up a floor (docs/layout.md, Floors):\n" + "\n".join(bad)


def _python_files() -> list[Path]:
    return sorted(p for d in ("tacgen_lib", "workflow", "tools") for p in (ROOT / d).rglob("*.py"))


@pytest.mark.parametrize("path", _python_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_over_max_lines(path):
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_LINES, (
        f"{path.relative_to(ROOT)}: {lines} lines; split it by concept (at most {MAX_LINES})"
    )


def smk_functions(root: Path = ROOT) -> list[tuple[str, int, int]]:
    """(file, line, length) of every function a `def` in the Snakefile or rules/*.smk defines
    (a Snakemake file is not Python, so its `def` lines are read as text: a function ends at the
    next line indented no deeper than its `def`)."""
    out = []
    for path in [root / "Snakefile", *sorted((root / "rules").glob("*.smk"))]:
        lines = path.read_text().splitlines()
        for i, line in enumerate(lines):
            stripped = line.lstrip()
            if not stripped.startswith("def "):
                continue
            indent, end = len(line) - len(stripped), i + 1
            while end < len(lines) and (
                not lines[end].strip() or len(lines[end]) - len(lines[end].lstrip()) > indent
            ):
                end += 1
            while not lines[end - 1].strip():
                end -= 1
            out.append((str(path.relative_to(root)), i + 1, end - i))
    return out


def test_smk_functions_are_read_from_a_rule_file(tmp_path):
    (tmp_path / "rules").mkdir()
    (tmp_path / "Snakefile").write_text("rule all:\n    input: []\n")
    (tmp_path / "rules" / "a.smk").write_text(
        "def f(w):\n    x = 1\n\n    return x\n\n\nrule r:\n    input: f\n"
    )
    assert smk_functions(tmp_path) == [("rules/a.smk", 1, 4)]


def test_the_rules_hold_no_second_program():
    found = smk_functions()
    long = [f"{f}:{line} ({n} lines)" for f, line, n in found if n > MAX_SMK_FUNCTION_LINES]
    assert len(found) <= MAX_SMK_FUNCTIONS, (
        f"{len(found)} functions in the rule files (at most {MAX_SMK_FUNCTIONS}); move the "
        "Python into tacgen_lib.plan"
    )
    assert not long, "rule-file functions over the limit: " + ", ".join(long)
