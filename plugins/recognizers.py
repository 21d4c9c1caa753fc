"""Built-in recognizer plugins."""

from __future__ import annotations

PLUGINS: list = []
