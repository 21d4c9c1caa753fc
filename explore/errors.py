"""Errors that the CLI turns into one clear line and an exit code."""

from __future__ import annotations


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
        where = self.source if not self.field else f"{self.source}: {self.field}"
        return f"{where}: {self.message}"


class RegistryError(BadInput):
    """An unknown plugin name, or two plugins that claim the same name."""


class MissionFailed(ExploreError):
    """The run ended without reaching its goal; reported in the metrics (exit code 1)."""
