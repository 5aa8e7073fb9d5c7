"""A rule's code inputs: the `tacgen_lib` modules its script reaches through imports (DESIGN §2).

Snakemake reruns a job when its script changes, not when a module the script imports changes.
So every rule declares, as inputs, the library modules its script imports, transitively; editing
one of them reruns exactly the jobs whose scripts reach it. The list is derived here from the
source with `ast`, never typed by hand: a hand-kept list drifts (it did, three times).

What counts as reached: every `import` and `from ... import` statement anywhere in a file (also
inside functions, which are imported when called), absolute or relative, whose target is inside
the library; for `from pkg import name`, `pkg/name.py` when `name` is a submodule; and the
`__init__.py` of every package on the way, since Python runs those too. Modules outside the
library (numpy, torch) are not inputs: the environment pins them.
"""

from __future__ import annotations

import ast
import os
from collections.abc import Iterable
from pathlib import Path

LIBRARY = "tacgen_lib"


def _module_file(lib_root: Path, dotted: str) -> Path | None:
    """The file of library module `dotted` ('tacgen_lib.io.edges'), or None if it is not one."""
    parts = dotted.split(".")
    if parts[0] != LIBRARY:
        return None
    base = lib_root.joinpath(*parts[1:])
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _package_of(lib_root: Path, path: Path) -> list[str]:
    """Dotted package parts of a library file (for resolving relative imports)."""
    rel = path.relative_to(lib_root.parent).with_suffix("")
    parts = list(rel.parts)
    return parts[:-1] if parts[-1] != "__init__" else parts[:-1]


#: The fields of a node that hold statements (import statements are statements: expressions
#: never hold one, so `_import_statements` does not descend into them).
_STATEMENT_FIELDS = ("body", "orelse", "finalbody", "handlers", "cases")


def _import_statements(tree: ast.AST) -> Iterable[ast.Import | ast.ImportFrom]:
    """Every import statement of a module, at any depth (in functions, classes, `if`, `try`,
    `with`, `match`): `ast.walk`'s import nodes, found without visiting expressions, which are
    most of a module's nodes (the workflow's ~50 closures at every Snakemake start: 0.45 s with
    `ast.walk`; equal sets on every library file, tests/io/test_code_inputs.py)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
            continue
        for field in _STATEMENT_FIELDS:
            children = getattr(node, field, None)
            if isinstance(children, list):
                stack.extend(children)


def _imported_names(tree: ast.AST, package: list[str]) -> Iterable[str]:
    """Dotted names a module's import statements may load (modules, or a module's attribute)."""
    for node in _import_statements(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = package[: len(package) - node.level + 1]
                base = ".".join([*anchor, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            yield base
            for alias in node.names:
                if alias.name != "*":
                    yield f"{base}.{alias.name}"


def _with_packages(lib_root: Path, dotted: str) -> list[Path]:
    """The module's file and the `__init__.py` of every package above it, in import order."""
    parts = dotted.split(".")
    out = []
    for i in range(1, len(parts) + 1):
        found = _module_file(lib_root, ".".join(parts[:i]))
        if found is None:
            break
        out.append(found)
    return out


#: (file, lib_root, mtime_ns, size) -> the library files its own import statements reach. The
#: workflow derives the closures of ~50 scripts at every Snakemake start and they share most
#: modules: each file is parsed once per process, and again only if it changes.
_DIRECT: dict[tuple[Path, Path, int, int], tuple[Path, ...]] = {}


def _direct_imports(path: Path, root: Path) -> tuple[Path, ...]:
    """Library files (with their packages' `__init__.py`) that `path`'s own imports reach."""
    stat = path.stat()
    key = (path, root, stat.st_mtime_ns, stat.st_size)
    if key not in _DIRECT:
        package = _package_of(root, path) if path.is_relative_to(root) else []
        tree = ast.parse(path.read_text(), filename=str(path))
        found = dict.fromkeys(
            f for dotted in _imported_names(tree, package) for f in _with_packages(root, dotted)
        )
        _DIRECT[key] = tuple(found)
    return _DIRECT[key]


def import_closure(script: str | os.PathLike[str], lib_root: str | os.PathLike[str]) -> list[Path]:
    """Every library file `script` reaches through imports, transitively, sorted.

    script: a Python file (a rule's script, or any module).
    lib_root: the `tacgen_lib` package folder.
    Raises FileNotFoundError for a missing script and SyntaxError (naming the file) for one
    that does not parse, so a broken script stops the workflow at parse time, not mid-run.
    """
    root = Path(lib_root).resolve()
    start = Path(script).resolve()
    if not start.is_file():
        raise FileNotFoundError(f"import_closure: no script {start}")
    seen: set[Path] = set()
    todo = [start]
    while todo:
        for found in _direct_imports(todo.pop(), root):
            if found not in seen:
                seen.add(found)
                todo.append(found)
    return sorted(seen - {start})


def code_inputs(
    script: str | os.PathLike[str], lib_root: str | os.PathLike[str], start: str = "."
) -> list[str]:
    """`import_closure` as paths relative to `start` (the workflow's working directory)."""
    return [os.path.relpath(p, start) for p in import_closure(script, lib_root)]
