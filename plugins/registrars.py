"""Built-in registrar plugins."""

from __future__ import annotations

PLUGINS: list = []
