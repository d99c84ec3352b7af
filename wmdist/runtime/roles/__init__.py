"""The actors of a run, one module per role (the table of roles is runtime/table.py)."""
