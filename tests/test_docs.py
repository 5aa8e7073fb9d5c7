"""The README is a user's guide and the docs describe methods: neither hand-copies a measured
figure (figures come from the run: the report, the benchmarks' output), every relative link
resolves, and config/README.md is the schema's own reference."""

from __future__ import annotations

import ast
import io
import re
import subprocess
import sys
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _number(text: str) -> str:
    """A number's value written one way (``0.20``, ``0.2`` and ``.2`` are one number)."""
    return repr(float(text))


def _stated_numbers() -> set[str]:
    """Every number the config files write and every number constant in the library's code
    (settings, defaults, constants such as a test level or the paper's reported figures):
    numbers a run does not measure. The library's comments and docstrings are not read: a
    figure there is prose, and prose holds no measurement (`test_no_measured_figure_in_the_code_prose`)."""
    config = "".join(p.read_text() for p in (ROOT / "config").glob("*.yaml"))
    known = {_number(x) for x in re.findall(r"\d+(?:\.\d+)?", config)}
    for path in (ROOT / "tacgen_lib").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and type(node.value) in (int, float):
                known.add(_number(repr(abs(node.value))))
    return known


#: numbers a page may state (`_stated_numbers`)
KNOWN = _stated_numbers()
#: a number with a unit of time, speed or size is a measurement wherever it stands
MEASURE_UNITS = ("s", "ms", "min", "h", "CPU-s", "GF/s", "GFLOP/s", "GB", "MB", "/s")
#: inline code in a line of prose (``double`` or `single` backticks): never a figure
_INLINE_CODE = re.compile(r"``.*?``|`[^`]*`")
#: a number, and its unit where one follows (a ratio as ``3×``, ``3 ×`` or ``3x``)
_NUMBER = re.compile(
    r"(?<![\w.~/-])([+−-]?\d[\d,]*(?:\.\d+)?)"
    r"(?:\s?(CPU-s|GFLOP/s|GF/s|min|ms|GB|MB|/s|s|h|×|%)|(x))?(?!\w|\.\d)"
)


def measured_figures(markdown: str) -> list[tuple[int, str]]:
    """(line, figure) of every number in prose or tables (code blocks, inline code and link
    targets left out) that reads as a measurement: a number with a unit of time, speed or size,
    a percentage with decimals, a ratio (×) or a decimal of two or more places that neither the
    config nor the library states."""
    text = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), markdown, flags=re.S)
    found = []
    for number, line in enumerate(text.split("\n"), 1):
        line = _INLINE_CODE.sub("", line)
        line = re.sub(r"\]\([^)]*\)", "]", line)
        for m in _NUMBER.finditer(line):
            value, unit = m.group(1), m.group(2) or ("×" if m.group(3) else None)
            plain = value.lstrip("+−-").replace(",", "")
            decimals = len(plain.split(".")[1]) if "." in plain else 0
            if unit in MEASURE_UNITS or (unit == "%" and decimals):
                found.append((number, m.group(0).strip()))
            # a speed-up, unless a setting's ratio
            elif unit == "×" and _number(plain) not in KNOWN:
                found.append((number, m.group(0).strip()))
            elif decimals >= 2 and _number(plain) not in KNOWN:
                found.append((number, m.group(0).strip()))
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_no_page_hand_copies_a_measured_figure(page):
    figures = measured_figures(page.read_text())
    assert not figures, f"{page.relative_to(ROOT)}: measured figures {figures[:10]}"


def test_the_scan_finds_what_a_lab_notebook_writes():
    notebook = (
        "The default DAG took 6 min 52 s (760 CPU-s).\n"
        "| hardness | +0.204 [+0.125, +0.279] |\n"
        "Sampling ran at 998 vectors/s, 1.37× faster; 12.5 % of jobs.\n"
        "```\nsnakemake --cores 2  # 3 min\n```\n"
        "τ = 0.07 and `lr: 0.0005` are settings; see [x](docs/a_1.25.md).\n"
    )
    found = [figure for _, figure in measured_figures(notebook)]
    assert found == ["6 min", "52 s", "760 CPU-s", "+0.204", "+0.125", "+0.279", "1.37×", "12.5 %"]


def test_the_readme_is_a_guide_with_the_two_commands():
    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 250
    assert "make run" in readme and "make test" in readme
    for page in (ROOT / "docs").glob("*.md"):
        assert f"docs/{page.name}" in readme, f"README.md does not point to docs/{page.name}"


@pytest.mark.parametrize("page", [*PAGES, ROOT / "config" / "README.md"], ids=lambda p: p.name)
def test_relative_links_resolve(page):
    for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
        if not target.startswith(("http://", "https://", "mailto:")):
            assert (page.parent / target).exists(), f"{page.name}: broken link {target}"


def test_config_reference_is_written_from_the_schema():
    proc = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "config_reference.py"), "--check"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr


#: Where the code's comments and docstrings live.
CODE_DIRS = ("tacgen_lib", "rules", "workflow", "tools", "benchmarks", "tests")
#: A path inside this repository named in a comment or docstring.
REPO_PATH = re.compile(
    r"(?<![\w./-])((?:docs|config|tools|tests|benchmarks|rules|workflow|profiles|envs)"
    r"/[\w./~{}-]*[\w}])"
)
#: Citations a reader of the repository cannot follow: files kept outside it, section marks
#: without a file, or notes of past work sessions.
OUTSIDE = re.compile(r"\bDESIGN\b|\bSTYLE\b|§|note of the stop|closing note")


def _code_files() -> list[Path]:
    files = []
    for d in CODE_DIRS:
        files += [p for p in (ROOT / d).rglob("*") if p.suffix in (".py", ".smk")]
    return sorted([*files, ROOT / "Snakefile"])


def _prose(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of a file's comments and triple-quoted strings (its docstrings and
    rule descriptions): what a reader follows, not what the code does."""
    out, in_doc = [], False
    for n, line in enumerate(path.read_text().splitlines(), 1):
        quotes = line.count('"""')
        if in_doc or quotes:
            out.append((n, line))
        if quotes % 2:
            in_doc = not in_doc
        elif not in_doc and "#" in line:
            out.append((n, line[line.index("#") :]))
    return out


def test_every_reference_in_the_code_resolves_inside_the_repository():
    """A comment or docstring names a file that exists here (a pattern with wildcards is
    checked up to its first wildcard), and never a file kept outside the repository."""
    this = Path(__file__).resolve()
    bad = []
    for path in _code_files():
        if path.resolve() == this:
            continue  # this test spells the patterns it refuses
        for n, line in _prose(path):
            if OUTSIDE.search(line):
                bad.append(f"{path.relative_to(ROOT)}:{n}: cites what is not in the repository")
            for ref in REPO_PATH.findall(line):
                stem = re.split(r"[{*]", ref)[0].rstrip("/")
                if stem and not any((ROOT / stem).parent.glob(Path(stem).name + "*")):
                    bad.append(f"{path.relative_to(ROOT)}:{n}: {ref} does not exist")
    assert not bad, "\n".join(bad[:20])


def test_the_reference_check_reads_comments_and_docstrings(tmp_path):
    f = tmp_path / "m.py"
    f.write_text(
        '"""A module (see DESIGN §3).\n\ndocs/x.md\n"""\nx = "config/no.yaml"  # tools/y\n'
    )
    assert [n for n, _ in _prose(f)] == [1, 2, 3, 4, 5]
    lines = dict(_prose(f))
    assert OUTSIDE.search(lines[1]) and REPO_PATH.findall(lines[3]) == ["docs/x.md"]
    assert REPO_PATH.findall(lines[5]) == ["tools/y"]  # the comment, not the string


def _docstrings_and_comments(path: Path) -> list[tuple[int, str]]:
    """(line number, text) of a Python file's docstrings and comments (its other strings are
    code: an XML template's coordinates are not prose); of a rules file's or the Snakefile's
    comments and triple-quoted strings (`_prose`); of a config file's comments."""
    text = path.read_text()
    if path.suffix == ".yaml":
        return [
            (n, line[line.index("#") :])
            for n, line in enumerate(text.splitlines(), 1)
            if "#" in line
        ]
    if path.suffix != ".py":
        return _prose(path)
    out = [
        (t.start[0], t.string)
        for t in tokenize.generate_tokens(io.StringIO(text).readline)
        if t.type == tokenize.COMMENT
    ]
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body[0] if node.body else None
            if isinstance(body, ast.Expr) and isinstance(body.value, ast.Constant):
                if isinstance(body.value.value, str):
                    lines = body.value.value.splitlines()
                    out += [(body.lineno + i, line) for i, line in enumerate(lines)]
    return sorted(out)


#: the code whose prose a reader of the project meets: the library, the rules, the workflow's
#: scripts, the tools and the config files
PROSE_FILES = sorted(
    [
        *(ROOT / "tacgen_lib").rglob("*.py"),
        *(ROOT / "workflow" / "scripts").glob("*.py"),
        *(ROOT / "tools").glob("*.py"),
        *(ROOT / "rules").glob("*.smk"),
        ROOT / "Snakefile",
        *(ROOT / "config").glob("*.yaml"),
    ]
)


#: a speed-up or slow-down as code prose writes one: ``5x``, ``~2x``, ``2-3x``, ``1.7×``
SPEEDUP = re.compile(r"(?<![\w.])~?\d+(?:\.\d+)?(?:-\d+(?:\.\d+)?)?[x×](?!\w|\.\d)")


def prose_figures(line: str) -> list[str]:
    """The measured figures of one line of code prose: `measured_figures`' and every
    speed-up (`SPEEDUP`), whatever the number (a page's ``2×`` may be a setting's ratio; a
    comment's ``2x faster`` is a measurement)."""
    found = [figure for _, figure in measured_figures(line)]
    plain = _INLINE_CODE.sub("", line)
    return found + [m.group(0).strip() for m in SPEEDUP.finditer(plain) if m.group(0) not in found]


@pytest.mark.parametrize("path", PROSE_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_measured_figure_in_the_code_prose(path):
    """Comments, docstrings and config comments say why, not how fast on which machine: a
    figure measured once goes stale with the code and the machine. Measurements come from
    what a benchmark prints (docs/cost.md lists them) and from the run's report."""
    found = [
        f"{path.relative_to(ROOT)}:{n}: {figure}  | {line.strip()[:100]}"
        for n, line in _docstrings_and_comments(path)
        for figure in prose_figures(line)
    ]
    assert not found, "\n".join(found)


def test_the_code_prose_reader_skips_code_strings(tmp_path):
    f = tmp_path / "m.py"
    f.write_text(
        '"""Module: took 3 s."""\n\nXML = """<geom size="0.25 0.013"/>"""  # 2x faster\n\n\n'
        'def g():\n    """Ran 1.7x slower."""\n'
    )
    got = [figure for _, line in _docstrings_and_comments(f) for figure in prose_figures(line)]
    assert got == ["3 s", "2x", "1.7x"]
