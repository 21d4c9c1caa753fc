"""Built-in pose_validator plugins."""

from __future__ import annotations

PLUGINS: list = []
