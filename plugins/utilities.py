"""Built-in utilitie plugins."""

from __future__ import annotations

PLUGINS: list = []
