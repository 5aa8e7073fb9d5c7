"""A rule's code inputs: the `tacgen_lib` modules its script reaches through imports (docs/cost.md and the README: only what changed reruns).

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
import hashlib
import itertools
import json
import os
from collections.abc import Iterable
from pathlib import Path

LIBRARY = "tacgen_lib"


#: lib_root -> (the mtime of each of its folders, dotted module name -> file): what a dotted
#: name can resolve to. ~50 closures resolve thousands of names at every Snakemake start; a
#: stat per candidate cost more than the rest together. Checked against the folders' mtimes
#: once per closure, so a module added or removed (which changes its folder's mtime) is seen.
_LISTINGS: dict[Path, tuple[dict[str, int], dict[str, Path], int]] = {}
_GENERATIONS = itertools.count()


def _library_modules(lib_root: Path) -> dict[str, Path]:
    """Dotted name -> file of every module and package under `lib_root` ('tacgen_lib.io' ->
    its `__init__.py`; a module file wins over a package of the same name, as Python's
    import does)."""
    have = _LISTINGS.get(lib_root)
    if have is not None:
        try:
            if all(os.stat(d).st_mtime_ns == m for d, m in have[0].items()):
                return have[1]
        except OSError:
            pass
    folders: dict[str, int] = {}
    modules: dict[str, Path] = {}
    packages: dict[str, Path] = {}
    for folder, subdirs, names in os.walk(lib_root):
        subdirs[:] = sorted(d for d in subdirs if d != "__pycache__")
        folders[folder] = os.stat(folder).st_mtime_ns
        rel = os.path.relpath(folder, lib_root)
        prefix = LIBRARY if rel == "." else ".".join([LIBRARY, *Path(rel).parts])
        for name in names:
            if not name.endswith(".py"):
                continue
            if name == "__init__.py":
                packages[prefix] = Path(folder, name)
            else:
                modules[f"{prefix}.{name[:-3]}"] = Path(folder, name)
    # a new generation for every listing: what was resolved against an older one is not reused
    _LISTINGS[lib_root] = (folders, {**packages, **modules}, next(_GENERATIONS))
    return _LISTINGS[lib_root][1]


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
    most of a module's nodes (the workflow's closures, at every Snakemake start; equal sets to
    `ast.walk`'s on every library file, tests/io/test_code_inputs.py)."""
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


def _with_packages(modules: dict[str, Path], dotted: str) -> list[Path]:
    """The module's file and the `__init__.py` of every package above it, in import order
    (modules: `_library_modules(lib_root)`; a name that is no library module ends the walk)."""
    parts = dotted.split(".")
    out = []
    for i in range(1, len(parts) + 1):
        found = modules.get(".".join(parts[:i]))
        if found is None:
            break
        out.append(found)
    return out


#: The imported names of each parsed file, by content: parsing (`ast.parse`) was most of the
#: closures' time at every Snakemake start, and the sources rarely change between starts. Keyed
#: by the SHA-1 of the file's bytes and its package (relative imports depend on it), so an
#: entry is right for any copy of the file anywhere; kept in the user's cache folder
#: (`$XDG_CACHE_HOME/tacgen-workflow`, `TACGEN_IMPORT_CACHE` overrides it, an empty value turns
#: it off) and in this process. Names are resolved to files afresh at every use.
_NAMES: dict[str, list[str]] = {}
CACHE_ENV = "TACGEN_IMPORT_CACHE"
_CACHE_VERSION = 1
_CACHE_MAX = 4000  # entries kept on disk: the newest (old versions of files drop out)
_cache_state = {"loaded": None, "dirty": False}


def _cache_file() -> Path | None:
    where = os.environ.get(CACHE_ENV)
    if where is not None:
        return Path(where) if where else None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base, "tacgen-workflow", f"imports-v{_CACHE_VERSION}.json")


def _load_cache() -> None:
    path = _cache_file()
    if _cache_state["loaded"] == path:
        return
    _cache_state["loaded"] = path
    if path is None:
        return
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError):
        return  # no cache yet, or a damaged one: parse
    if isinstance(stored, dict):
        for key, names in stored.items():
            if isinstance(names, list) and all(isinstance(n, str) for n in names):
                _NAMES.setdefault(key, names)


def _save_cache() -> None:
    """Write the cache atomically (a temporary file renamed into place); never fail a run."""
    path = _cache_file()
    if path is None or not _cache_state["dirty"]:
        return
    keep = dict(list(_NAMES.items())[-_CACHE_MAX:])
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(keep))
        os.replace(tmp, path)
        _cache_state["dirty"] = False
    except OSError:
        pass


#: (file, mtime_ns, size, the listing it was resolved against) -> its direct imports: the ~50
#: closures of one Snakemake start share most modules; each is read and resolved once.
_RESOLVED: dict[tuple[Path, int, int, int], tuple[Path, ...]] = {}


def _direct_imports(path: Path, root: Path, modules: dict[str, Path]) -> tuple[Path, ...]:
    """Library files (with their packages' `__init__.py`) that `path`'s own imports reach."""
    stat = path.stat()
    memo = (path, stat.st_mtime_ns, stat.st_size, _LISTINGS[root][2])
    if memo in _RESOLVED:
        return _RESOLVED[memo]
    source = path.read_bytes()
    package = _package_of(root, path) if path.is_relative_to(root) else []
    key = f"{hashlib.sha1(source).hexdigest()}|{'.'.join(package)}"
    names = _NAMES.get(key)
    if names is None:
        tree = ast.parse(source, filename=str(path))
        names = list(dict.fromkeys(_imported_names(tree, package)))
        _NAMES[key] = names
        _cache_state["dirty"] = True
    found = tuple(dict.fromkeys(f for dotted in names for f in _with_packages(modules, dotted)))
    _RESOLVED[memo] = found
    return found


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
    _load_cache()
    modules = _library_modules(root)
    seen: set[Path] = set()
    todo = [start]
    while todo:
        for found in _direct_imports(todo.pop(), root, modules):
            if found not in seen:
                seen.add(found)
                todo.append(found)
    _save_cache()
    return sorted(seen - {start})


def code_inputs(
    script: str | os.PathLike[str], lib_root: str | os.PathLike[str], start: str = "."
) -> list[str]:
    """`import_closure` as paths relative to `start` (the workflow's working directory)."""
    return [os.path.relpath(p, start) for p in import_closure(script, lib_root)]
