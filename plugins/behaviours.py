"""Built-in behaviour plugins."""

from __future__ import annotations

PLUGINS: list = []
