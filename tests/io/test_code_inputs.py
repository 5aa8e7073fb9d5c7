"""Code inputs derived from imports: every rule declares exactly the library modules it reaches.

The library's `import_closure` reads the source with `ast`; the reference here is the standard
library's `modulefinder`, which follows the compiled bytecode instead, restricted to this
repository so that numpy or torch are never walked.
"""

from __future__ import annotations

import functools
import modulefinder
import re
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest
from snakemake_run import ROOT

from tacgen_lib.io.imports import code_inputs, import_closure

LIB = ROOT / "tacgen_lib"
SCRIPTS = ROOT / "workflow" / "scripts"


@functools.cache
def modulefinder_closure(script: Path) -> frozenset[str]:
    """Library files a script reaches, by the standard library's bytecode-following finder.
    Once per script and process: the dry-run test checks ~140 jobs of ~50 scripts against it
    (the library does not change during a test session)."""
    finder = modulefinder.ModuleFinder(path=[str(ROOT)])
    finder.run_script(str(script))
    return frozenset(
        str(Path(m.__file__).resolve().relative_to(ROOT))
        for name, m in finder.modules.items()
        if name.split(".")[0] == "tacgen_lib" and m.__file__
    )


def rule_scripts() -> dict[str, tuple[str, str | None]]:
    """rule -> (its script's stem, the script named in its `code=imports_of(...)` or None)."""
    out = {}
    for smk_file in sorted((ROOT / "rules").glob("*.smk")):
        for block in re.split(r"(?m)^(?=rule )", smk_file.read_text())[1:]:
            name = re.match(r"rule (\w+):", block).group(1)
            script = re.search(r'script:\n\s+"\.\./workflow/scripts/(\w+)\.py"', block)
            if script is None:
                continue
            declared = re.search(r'code=imports_of\("(\w+)"\)', block)
            out[name] = (script.group(1), declared.group(1) if declared else None)
    return out


def test_every_scripted_rule_declares_the_imports_of_its_own_script():
    scripts = rule_scripts()
    assert len(scripts) >= 15
    wrong = {rule: pair for rule, pair in scripts.items() if pair[0] != pair[1]}
    assert not wrong, f"rules whose code= input is missing or names another script: {wrong}"


@pytest.mark.parametrize("script", sorted(p.stem for p in SCRIPTS.glob("*.py")))
def test_import_closure_equals_modulefinder(script):
    path = SCRIPTS / f"{script}.py"
    got = {str(p.relative_to(ROOT)) for p in import_closure(path, LIB)}
    assert got == modulefinder_closure(path)
    assert "tacgen_lib/io/log.py" in got  # every script logs


@pytest.mark.workflow
def test_dry_run_inputs_of_every_job_are_its_scripts_import_closure(cold_dry_run):
    """What Snakemake sees as each job's library inputs equals what its script reaches (the
    dry run of a fresh copy of the repository, conftest.cold_dry_run)."""
    proc = cold_dry_run
    scripts = rule_scripts()
    seen = set()
    for rule, inputs in re.findall(
        r"\nrule (\w+):\n    input: ([^\n]*)", proc.stdout + proc.stderr
    ):
        if rule not in scripts:
            continue
        declared = {f for f in inputs.split(", ") if f.startswith("tacgen_lib/")}
        want = modulefinder_closure(SCRIPTS / f"{scripts[rule][0]}.py")
        assert declared == want, rule
        seen.add(rule)
    assert {"simulate_corpus", "train_heads", "probe", "aggregate_probes"} <= seen


def write_library(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return root / "tacgen_lib"


def test_closure_follows_relative_function_level_and_package_imports(tmp_path):
    lib = write_library(
        tmp_path,
        {
            "tacgen_lib/__init__.py": "",
            "tacgen_lib/a/__init__.py": "",
            "tacgen_lib/a/one.py": "from . import two\n",
            "tacgen_lib/a/two.py": "def f():\n    from ..b import three\n",
            "tacgen_lib/b/__init__.py": "import numpy\n",
            "tacgen_lib/b/three.py": "from tacgen_lib.b.four import NAME\n",
            "tacgen_lib/b/four.py": "NAME = 1\n",
            "tacgen_lib/b/unused.py": "",
            "script.py": "import os\nfrom tacgen_lib.a import one\n",
        },
    )
    got = [p.relative_to(tmp_path).as_posix() for p in import_closure(tmp_path / "script.py", lib)]
    assert got == [
        "tacgen_lib/__init__.py",
        "tacgen_lib/a/__init__.py",
        "tacgen_lib/a/one.py",
        "tacgen_lib/a/two.py",
        "tacgen_lib/b/__init__.py",
        "tacgen_lib/b/four.py",
        "tacgen_lib/b/three.py",
    ]
    assert code_inputs(tmp_path / "script.py", lib, start=tmp_path)[0] == "tacgen_lib/__init__.py"


def test_closure_names_a_script_that_does_not_parse(tmp_path):
    lib = write_library(tmp_path, {"tacgen_lib/__init__.py": "", "bad.py": "import (\n"})
    with pytest.raises(SyntaxError, match="bad.py"):
        import_closure(tmp_path / "bad.py", lib)
    with pytest.raises(FileNotFoundError, match="missing.py"):
        import_closure(tmp_path / "missing.py", lib)


def one_two_three_library(root: Path, one: str) -> Callable[[], list[str]]:
    """A library whose module `one` holds the source `one` (importing `two` or `three`), and
    a script importing `one`: returns the script's closure as file names, computed afresh."""
    lib = write_library(
        root,
        {
            "tacgen_lib/__init__.py": "",
            "tacgen_lib/one.py": one,
            "tacgen_lib/two.py": "",
            "tacgen_lib/three.py": "",
            "script.py": "from tacgen_lib import one\n",
        },
    )
    return lambda: [p.name for p in import_closure(root / "script.py", lib)]


def test_closure_follows_an_edit_made_after_a_first_closure_in_the_same_process(tmp_path):
    """Parsed files are remembered per process (one parse per Snakemake start); an edited
    file is parsed again, so the new import is followed and the dropped one is not."""
    closure = one_two_three_library(tmp_path, "from tacgen_lib import two\n")
    lib = tmp_path / "tacgen_lib"

    assert closure() == ["__init__.py", "one.py", "two.py"]
    (lib / "one.py").write_text("from tacgen_lib import three  # an edit of a parsed file\n")
    assert closure() == ["__init__.py", "one.py", "three.py"]


@pytest.fixture
def fresh_process(monkeypatch, tmp_path):
    """The import module as a new process finds it: nothing parsed or resolved in memory, the
    parse cache at a file of this test. Returns the cache file."""
    import tacgen_lib.io.imports as imports

    cache = tmp_path / "cache" / "imports.json"
    monkeypatch.setenv(imports.CACHE_ENV, str(cache))

    def restart() -> None:
        imports._NAMES.clear()
        imports._RESOLVED.clear()
        imports._LISTINGS.clear()
        imports._cache_state.update(loaded=None, dirty=False)

    restart()
    yield cache, restart
    restart()


def test_a_new_process_takes_parsed_imports_from_the_cache_and_parses_only_edits(
    tmp_path, fresh_process, monkeypatch
):
    import ast

    cache, restart = fresh_process
    closure = one_two_three_library(tmp_path, "from . import two\n")
    lib = tmp_path / "tacgen_lib"

    want = closure()
    assert want == ["__init__.py", "one.py", "two.py"] and cache.is_file()
    parsed: list[str] = []
    real_parse = ast.parse

    def counting_parse(source, filename="<unknown>", *args, **kwargs):
        parsed.append(Path(filename).name)
        return real_parse(source, filename, *args, **kwargs)

    monkeypatch.setattr(ast, "parse", counting_parse)
    restart()
    assert closure() == want and parsed == []  # every file from the cache
    (lib / "one.py").write_text("from . import three\n")
    restart()
    assert closure() == ["__init__.py", "one.py", "three.py"] and parsed == ["one.py"]


def test_a_damaged_cache_is_ignored_and_rewritten(tmp_path, fresh_process):
    import json

    cache, restart = fresh_process
    lib = write_library(
        tmp_path,
        {
            "tacgen_lib/__init__.py": "",
            "tacgen_lib/one.py": "",
            "script.py": "import tacgen_lib.one\n",
        },
    )
    cache.parent.mkdir(parents=True)
    for damage in ("{not json", '{"x": [1, 2]}', "[]"):
        cache.write_text(damage)
        restart()
        assert [p.name for p in import_closure(tmp_path / "script.py", lib)] == [
            "__init__.py",
            "one.py",
        ]
        assert all(isinstance(v, list) for v in json.loads(cache.read_text()).values())


def test_a_module_added_after_a_first_closure_is_resolved(tmp_path, fresh_process):
    """`from pkg import name` reaches pkg/name.py once that file exists, in the same process
    (the listing of the library is checked against its folders at every closure)."""
    lib = write_library(
        tmp_path,
        {
            "tacgen_lib/__init__.py": "",
            "tacgen_lib/pkg/__init__.py": "name = 1\n",
            "script.py": "from tacgen_lib.pkg import name\n",
        },
    )

    def closure() -> list[str]:
        return [p.relative_to(lib).as_posix() for p in import_closure(tmp_path / "script.py", lib)]

    assert closure() == ["__init__.py", "pkg/__init__.py"]
    (lib / "pkg" / "name.py").write_text("")
    assert closure() == ["__init__.py", "pkg/__init__.py", "pkg/name.py"]


def test_an_empty_cache_setting_writes_no_cache(tmp_path, fresh_process, monkeypatch):
    import tacgen_lib.io.imports as imports

    cache, restart = fresh_process
    monkeypatch.setenv(imports.CACHE_ENV, "")
    restart()
    lib = write_library(
        tmp_path, {"tacgen_lib/__init__.py": "", "script.py": "import tacgen_lib\n"}
    )
    assert [p.name for p in import_closure(tmp_path / "script.py", lib)] == ["__init__.py"]
    assert not cache.parent.exists()


def test_the_snakefile_parses_without_the_numerics_libraries():
    """What every Snakemake start (and every cluster job, which parses the Snakefile again)
    imports from tacgen_lib: the modules the Snakefile and rules/*.smk import at their top
    level, with what they import in turn (the plan, `tacgen_lib.plan.stages`, reaches every
    stage's settings; a module imported inside a function pays only where it runs). None of
    them may pull in scikit-learn, SciPy or torch (scikit-learn and SciPy cost ~1 s of a ~3 s
    dry run before the probes' settings moved to `probes.settings`)."""
    import subprocess
    import sys

    sources = [ROOT / "Snakefile", *sorted((ROOT / "rules").glob("*.smk"))]
    modules = sorted(
        {
            m
            for src in sources
            for m in re.findall(r"^from (tacgen_lib[\w.]*) import", src.read_text(), re.MULTILINE)
        }
    )
    assert "tacgen_lib.plan.stages" in modules, modules  # every stage's plan, imports and all
    code = (
        f"import sys; import {', '.join(modules)}; "
        "print(sorted(m for m in ('sklearn', 'scipy', 'torch') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]", f"parse-time imports load {out.stdout.strip()}: {modules}"


def test_import_statements_are_ast_walks_on_every_library_file_and_script():
    """`_import_statements` visits statements only: on every file of the library and every
    workflow script it finds the very import nodes `ast.walk` finds, plus a module that nests
    imports in every kind of block."""
    import ast

    from tacgen_lib.io.imports import _import_statements

    nested = textwrap.dedent(
        """
        import a
        def f():
            class C:
                import b
            if x:
                import c
            elif y:
                from . import d
            else:
                from e import g
            for i in r:
                import h
            else:
                import i
            while t:
                import j
            with m:
                import k
            try:
                import l
            except E:
                import n
            else:
                import o
            finally:
                import p
            match v:
                case 1:
                    import q
        async def g():
            async with m:
                import s
            async for i in r:
                import t
        """
    )
    files = [
        *sorted((ROOT / "tacgen_lib").rglob("*.py")),
        *sorted(ROOT.glob("workflow/scripts/*.py")),
    ]
    sources = [(str(p), p.read_text()) for p in files] + [("nested", nested)]
    for name, source in sources:
        tree = ast.parse(source)
        walked = [n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)]
        found = list(_import_statements(tree))
        assert sorted(map(id, found)) == sorted(map(id, walked)), name
    assert len(list(_import_statements(ast.parse(nested)))) == 16
