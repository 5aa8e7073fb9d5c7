"""TacGen workflow numerics: every computation the Snakemake rules call lives here."""

__version__ = "0.1.0"
