"""Built-in strategie plugins."""

from __future__ import annotations

PLUGINS: list = []
