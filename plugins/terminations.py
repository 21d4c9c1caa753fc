"""Built-in termination plugins."""

from __future__ import annotations

PLUGINS: list = []
