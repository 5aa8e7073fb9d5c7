"""Logging for rule scripts: progress lines to the rule's `log:` file (and stderr).

`for_rule(snakemake)` is the one call a script makes first. Lines carry a timestamp and the
rule name; where a preloaded interpreter serves the run but the job ran fresh, the log says why
(`tacgen_lib.runtime.preload.fresh_reason`). An uncaught exception is written to the log as
`rule <name> failed: <message>` before Python prints the traceback, so the log alone says what
went wrong and where.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["to_file", "for_rule", "Progress"]


def to_file(path: str | Path, name: str = "tacgen") -> logging.Logger:
    """A logger writing to `path` (truncated) and to stderr."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    logger = logging.getLogger(f"{name}:{path}")
    logger.setLevel(logging.INFO)
    logger.handlers.clear()
    logger.propagate = False
    fmt = logging.Formatter(f"%(asctime)s {name} %(levelname)s %(message)s", "%H:%M:%S")
    for handler in (logging.FileHandler(path, mode="w"), logging.StreamHandler(sys.stderr)):
        handler.setFormatter(fmt)
        logger.addHandler(handler)
    return logger


def for_rule(smk: Any) -> logging.Logger:
    """Logger for a Snakemake `script:` job: the rule's log file, the rule's name, wildcards."""
    rule = getattr(smk, "rule", "rule")
    logger = to_file(smk.log[0], name=rule)
    wildcards = dict(smk.wildcards.items()) if hasattr(smk.wildcards, "items") else {}
    logger.info("start %s", " ".join(f"{k}={v}" for k, v in wildcards.items()) or "")
    preload = sys.modules.get("tacgen_lib.runtime.preload")  # the script's first import
    why = preload.fresh_reason() if preload is not None else None
    if why:
        logger.info("runs in a fresh interpreter, not the preloaded one: %s", why)
    previous = sys.excepthook

    def hook(exc_type, exc, tb):  # noqa: ANN001 - signature fixed by sys.excepthook
        logger.error("rule %s failed: %s: %s", rule, exc_type.__name__, exc)
        previous(exc_type, exc, tb)

    sys.excepthook = hook
    return logger


class Progress:
    """Rate-limited progress lines: `tick(done)` logs at most every `every` seconds."""

    def __init__(self, logger: logging.Logger, total: int, what: str, every: float = 5.0):
        self.logger, self.total, self.what, self.every = logger, total, what, every
        self.start = self.last = time.perf_counter()

    def tick(self, done: int) -> None:
        now = time.perf_counter()
        if now - self.last >= self.every or done == self.total:
            rate = done / max(now - self.start, 1e-9)
            self.logger.info("%s %d/%d (%.1f/s)", self.what, done, self.total, rate)
            self.last = now
