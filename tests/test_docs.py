"""The README is a user's guide and the docs describe methods: neither hand-copies a measured
figure (figures come from the run: the report, the benchmarks' output), every relative link
resolves, and config/README.md is the schema's own reference."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

#: numbers a page may state: every number written in the config files and the library's source
#: (settings, defaults, constants such as a test level), which a run does not measure
_SOURCES = [*(ROOT / "config").glob("*.yaml"), *(ROOT / "tacgen_lib").rglob("*.py")]
KNOWN = set(re.findall(r"\d+(?:\.\d+)?", "".join(p.read_text() for p in _SOURCES)))
#: a number with a unit of time, speed or size is a measurement wherever it stands
MEASURE_UNITS = ("s", "ms", "min", "h", "CPU-s", "GF/s", "GFLOP/s", "GB", "MB", "/s")
_NUMBER = re.compile(
    r"(?<![\w.~/-])([+−-]?\d[\d,]*(?:\.\d+)?)\s?(CPU-s|GFLOP/s|GF/s|min|ms|GB|MB|/s|s|h|×|%)?(?![\w.])"
)


def measured_figures(markdown: str) -> list[tuple[int, str]]:
    """(line, figure) of every number in prose or tables (code blocks, inline code and link
    targets left out) that reads as a measurement: a number with a unit of time, speed or size,
    a percentage with decimals, a ratio (×) or a decimal of two or more places that neither the
    config nor the library states."""
    text = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), markdown, flags=re.S)
    found = []
    for number, line in enumerate(text.split("\n"), 1):
        line = re.sub(r"`[^`]*`", "", line)
        line = re.sub(r"\]\([^)]*\)", "]", line)
        for m in _NUMBER.finditer(line):
            value, unit = m.group(1), m.group(2)
            plain = value.lstrip("+−-").replace(",", "")
            decimals = len(plain.split(".")[1]) if "." in plain else 0
            if unit in MEASURE_UNITS or (unit == "%" and decimals):
                found.append((number, m.group(0).strip()))
            elif unit == "×" and plain not in KNOWN:  # a speed-up, unless a setting's ratio
                found.append((number, m.group(0).strip()))
            elif decimals >= 2 and plain not in KNOWN:
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
