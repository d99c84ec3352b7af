"""Batched MCTS for the MuZero family (pUCT, Gumbel MuZero, EfficientZero value prefix).

Public API: `SearchConfig`, `SearchOutput`, `search` (see `api.py` for the conventions).
`reference.py` is a slow one-root search used only by tests; `testing.py` holds fake models.
"""
from wmdist.search.api import SearchConfig, SearchOutput, search

__all__ = ["SearchConfig", "SearchOutput", "search"]
