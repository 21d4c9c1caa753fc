"""Errors that the CLI turns into one clear line and an exit code."""

from __future__ import annotations

import difflib
import reprlib
from collections.abc import Sequence
from typing import Any

MAX_LINE = 300  # characters of an error line
_BRIEF = reprlib.Repr()
_BRIEF.maxlevel, _BRIEF.maxstring, _BRIEF.maxother, _BRIEF.maxlong = 2, 48, 48, 24
_BRIEF.maxtuple = _BRIEF.maxlist = _BRIEF.maxdict = _BRIEF.maxset = 4


def valid_names(name: str, valid: Sequence[str], listing: str = "") -> str:
    """The valid names for an error line: all of them when few, else the close matches and where the rest are."""
    valid = sorted(valid)
    if not valid:
        return "(none exist)"
    if len(valid) <= 10:
        return f"(valid: {', '.join(valid)})"
    close = difflib.get_close_matches(str(name), valid, n=4, cutoff=0.5)
    where = f"; {listing} lists all {len(valid)}" if listing else f"; {len(valid)} exist"
    return f"(did you mean {', '.join(close)}?{where})" if close else f"({', '.join(valid[:6])}, ...{where})"


def brief(value: Any) -> str:
    """A short repr of a user's value for an error line (bounded work for any size of value)."""
    return _BRIEF.repr(value)


class ExploreError(Exception):
    """Base class of the errors explore raises on purpose."""


class BadInput(ExploreError):
    """Input a user can fix: a file, the field in it, and what is wrong (exit code 2)."""

    def __init__(self, source: str, field: str | None, message: str) -> None:
        self.source = str(source)
        self.field = field
        self.message = message
        super().__init__(self.line())

    def line(self) -> str:
        """``file: field: what is wrong`` on one line of at most :data:`MAX_LINE` characters."""
        where = self.source if not self.field else f"{self.source}: {self.field}"
        text = " ".join(f"{where}: {self.message}".split())
        return text if len(text) <= MAX_LINE else text[: MAX_LINE - 1] + "…"


class RegistryError(BadInput):
    """An unknown plugin name, or two plugins that claim the same name."""


class PluginCheckFailed(BadInput):
    """A plugin's own consistency check on its parameters failed (e.g. max_range below min_range);
    ``kind`` says which plugin kind, so a caller can tell whose parameters to name."""

    def __init__(self, source: str, field: str | None, message: str, kind: str) -> None:
        self.kind = kind
        super().__init__(source, field, message)


class MissionFailed(ExploreError):
    """The run ended without reaching its goal; reported in the metrics (exit code 1)."""


class Terminated(KeyboardInterrupt):  # noqa: N818 - a signal, like KeyboardInterrupt
    """SIGTERM, raised in the main thread: a run ends as on an interrupt (its results written), exit 143."""
