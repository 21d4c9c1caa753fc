"""Built-in executor plugins."""

from __future__ import annotations

PLUGINS: list = []
