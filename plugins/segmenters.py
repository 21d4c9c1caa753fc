"""Built-in segmenter plugins."""

from __future__ import annotations

PLUGINS: list = []
