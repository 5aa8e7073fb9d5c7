"""The report: tables, figures and the cost of accuracy, built from the stages' edges.

Importing any module of this package selects matplotlib's Agg backend first (here, once), so
figures render headless on every machine, and `tacgen_lib.report.write` is the one way a
figure or table reaches disk: atomically, with no timestamps, so a rerun gives the same bytes.
"""

import matplotlib

matplotlib.use("Agg")
