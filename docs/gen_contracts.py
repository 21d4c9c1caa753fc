"""Write the "Contracts" section of docs/writing-plugins.md from the docstrings of explore.api.

usage: python docs/gen_contracts.py   (tests/test_api.py checks that the section is current)
"""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

DOC = Path(__file__).with_name("writing-plugins.md")
BEGIN, END = "<!-- contracts:begin (docs/gen_contracts.py) -->", "<!-- contracts:end -->"


def _methods(cls: type) -> list[tuple[str, str, bool]]:
    """(signature, first docstring paragraph, abstract) of the public methods a contract declares."""
    out = []
    for name, member in cls.__dict__.items():
        if name.startswith("_") or not callable(member) and not isinstance(member, property):
            continue
        func = member.fget if isinstance(member, property) else member
        doc = " ".join((inspect.getdoc(func) or "").split("\n\n")[0].split())
        signature = name if isinstance(member, property) else f"{name}{inspect.signature(func)}"
        out.append((signature.replace("self, ", "").replace("(self)", "()"), doc,
                    bool(getattr(func, "__isabstractmethod__", False))))
    return out


def _cell(text: str) -> str:
    """Table-safe: string annotations unquoted, pipes escaped."""
    return text.replace("'", "").replace("|", "\\|")


def _contract(cls: type) -> list[str]:
    """A contract's docstring and the table of its methods."""
    lines = [inspect.getdoc(cls) or "", ""]
    methods = _methods(cls)
    if methods:
        lines += ["| method | must implement | what |", "| --- | --- | --- |"]
        lines += [f"| `{_cell(sig)}` | {'yes' if abstract else ''} | {_cell(doc)} |" for sig, doc, abstract in methods]
        lines.append("")
    return lines


def render() -> str:
    from explore.api import CONTRACTS

    aliases = {"sensor": "Sensor", "behaviour": "Behaviour"}  # RaySensor, ExploreBehaviour in the library
    lines = [BEGIN, ""]
    for kind, cls in CONTRACTS.items():
        lines += [f"### `{kind}`: `explore.api.{aliases.get(kind, cls.__name__)}`", ""]
        lines += _contract(cls)
        # contracts by role (e.g. the registrars) are the kind's subclasses in the same module
        for sub in (s for s in cls.__subclasses__() if s.__module__ == cls.__module__ and getattr(s, "role", "")):
            lines += [f"#### `explore.api.{sub.__name__}` (role `{sub.role}`)", ""] + _contract(sub)
    lines.append(END)
    return "\n".join(lines)


def main() -> int:
    text = DOC.read_text(encoding="utf-8")
    head, _, rest = text.partition(BEGIN)
    _, _, tail = rest.partition(END)
    DOC.write_text(head + render() + tail, encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
