"""The one error type configuration problems raise: its message is a single line."""
from __future__ import annotations

import difflib
from typing import Iterable


class ConfigError(ValueError):
    """A config problem found before anything starts; `str(err)` is one line for the user."""


def closest(word: str, options: Iterable[str]) -> str:
    """' (did you mean 'x'?)' for the closest option, or '' when none is close."""
    match = difflib.get_close_matches(word, list(options), n=1, cutoff=0.5)
    return f" (did you mean '{match[0]}'?)" if match else ""


def first_line(err: BaseException) -> str:
    """The first non-blank line of an exception's message (its type name when it has none), for
    one-line errors built from exceptions whose text may span many lines."""
    lines = [ln.strip() for ln in str(err).strip().splitlines() if ln.strip()]
    return (lines[0] if lines else type(err).__name__)[:300]


def mismatch_line(err: BaseException) -> str:
    """The informative line of a failed `load_state_dict` (torch's first line is only 'Error(s) in
    loading state_dict for Model:'): the first size mismatch or missing/unexpected key."""
    lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
    for ln in lines:
        if ln.startswith(("size mismatch", "Missing key", "Unexpected key")):
            return ln[:300]
    return first_line(err)
