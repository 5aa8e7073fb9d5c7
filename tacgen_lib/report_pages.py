"""The report's pages (Snakemake report categories) in the paper's order.

Snakemake's viewer sorts categories as text, so each carries its position as a two-digit
prefix (`category`): the reader meets the findings first, then corpus → preprocessing →
features → alignment → probes → robustness → backbone families → transfer to a second
sensor → generation → where generated touch helps → touch to language → policy → cost → provenance. Kept
apart from `tacgen_lib.report` (which loads matplotlib) because the DAG reads it at parse time.
"""

from __future__ import annotations

__all__ = ["FINDINGS_COLUMNS", "PAGES", "category", "page_of"]

#: The columns of the findings page's table, one row per finding (`tacgen_lib.report.findings`).
FINDINGS_COLUMNS = ["evidence", "question", "result", "control", "verdict", "page"]

PAGES = (
    "Findings",
    "Corpus",
    "Preprocessing",
    "Features",
    "What vision sees",
    "Alignment",
    "Probes",
    "Robustness",
    "Backbone families",
    "Transfer to a second sensor",
    "Generation",
    "Where generated touch helps",
    "Pixel generators",
    "Touch to language",
    "Policy",
    "Cost of accuracy",
    "Provenance",
)


def category(page: str) -> str:
    """The report category of `page`: its position in `PAGES` and its name ("01 Findings")."""
    if page not in PAGES:
        raise KeyError(f"report page {page!r} is not one of {', '.join(PAGES)}")
    return f"{PAGES.index(page) + 1:02d} {page}"


def page_of(category_name: str) -> str:
    """The page name of a category ("06 Probes" -> "Probes")."""
    head, _, rest = category_name.partition(" ")
    return rest if head.isdigit() and rest else category_name
