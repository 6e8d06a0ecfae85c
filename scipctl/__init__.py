"""scipctl: ground tool for Single Cycle Instrument Placement (SCIP)."""

__version__ = "0.1.0"
