"""Built-in planner plugins."""

from __future__ import annotations

PLUGINS: list = []
