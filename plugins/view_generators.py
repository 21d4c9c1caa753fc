"""Built-in view_generator plugins."""

from __future__ import annotations

PLUGINS: list = []
