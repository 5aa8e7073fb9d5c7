"""The workflow's plan: what the rules of `rules/*.smk` expand, ask for and name, read from the
validated config (`tacgen_lib.workflow_config.validate_config`).

One module per stage, each a plain object built from the config (`paths` holds the path
families every stage shares). The `.smk` files hold rules and the imports of these objects; the
Python that decides which grid cells, edges, benchmark files and inputs a rule has lives here,
under ruff and pytest like the rest of the library (docs/layout.md).
"""
