"""Files that users write (worlds, trees, results.csv, ``--set`` values), read so that any bad file gives one line.

Beyond PyYAML's safe loader: the file must be UTF-8 text of a sensible size; a mapping may
not repeat a key (PyYAML silently keeps the last one); aliases may not expand the document
beyond :data:`MAX_NODES` nodes (a "billion laughs" file is rejected in milliseconds instead of
being walked and printed); recursive aliases, absurd nesting and keys that are not text (``0E0:``
is a number) are rejected too.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from explore.core.errors import BadInput

TEXT_TAG, MERGE_TAG = "tag:yaml.org,2002:str", "tag:yaml.org,2002:merge"
MAX_BYTES = 8 * 2**20
MAX_NODES = 100_000  # nodes of the document with every alias expanded
NAME_MAX = 255  # bytes of one path component (Linux, macOS)
# an object's name: a database key and part of file names (the database's mesh files, pictures)
OBJECT_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,99}$")
OBJECT_NAME_RULE = "up to 100 letters, digits, _ . -"


def check_path_name(path: str | Path, option: str | None = None) -> Path:
    """``path`` if no component is longer than the file system allows.

    ``Path.is_file`` raises (instead of answering False) for such a name, so every lookup of a
    user's file or name (world, tree, mesh, database, output) checks it first.
    """
    text = str(path)
    if any(len(part.encode()) > NAME_MAX for part in Path(text).parts):
        shown = text[:60] + "…"
        file, where = (option, shown) if option else (shown, None)
        raise BadInput(file, where, f"a name longer than {NAME_MAX} bytes")
    return Path(text)


def read_text(path: str | Path) -> str:
    """A file's UTF-8 text; unreadable, too large or not UTF-8 is a BadInput naming the line."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as error:
        raise BadInput(str(path), None, f"cannot read: {error.strerror or error}") from None
    if len(data) > MAX_BYTES:
        raise BadInput(str(path), None, f"{len(data)} bytes, more than the {MAX_BYTES} a text input may have")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data[: error.start].count(b"\n") + 1
        raise BadInput(str(path), f"line {line}", f"not UTF-8 text (byte 0x{data[error.start]:02x})") from None


def load_yaml(path: str | Path) -> Any:
    """Read and parse a YAML file (see the module docstring for what is rejected)."""
    return parse_yaml(read_text(path), str(path))


def parse_yaml(text: str, source: str) -> Any:
    """Parse YAML text; every problem is a :class:`BadInput` of ``source`` with the line."""
    loader = None
    try:
        loader = _Loader(text)
        node = loader.get_single_node()
        if node is None:
            return None
        _check(node, source)
        return loader.construct_document(node)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else None
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise BadInput(source, where, f"malformed YAML: {problem}") from None
    except RecursionError:
        raise BadInput(source, None, "malformed YAML: nested too deeply") from None
    finally:
        if loader is not None:
            loader.dispose()


class _Loader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2 booleans and floats. Booleans: only true/false (YAML 1.1 also
    reads yes/no/on/off as booleans, which turned the tree attribute ``on:`` of a one_shot node into the
    key True). Floats: also an exponent without a dot, ``5e-3`` (YAML 1.1 asks for ``5.0e-3`` and
    reads ``5e-3`` as the string '5e-3')."""


_Loader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag != "tag:yaml.org,2002:bool"]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver("tag:yaml.org,2002:bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"),
                              list("tTfF"))
_Loader.add_implicit_resolver("tag:yaml.org,2002:float",
                              re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789"))


def _line(node: yaml.Node) -> str:
    return f"line {node.start_mark.line + 1}"


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _check(root: yaml.Node, source: str) -> None:
    """Duplicate keys, recursive aliases and the alias-expanded size, in one pass over the node graph."""
    size: dict[int, int] = {}
    open_: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, finish = stack.pop()
        key = id(node)
        if finish:
            open_.discard(key)
            size[key] = 1 + sum(size[id(c)] for c in _children(node))
            if size[key] > MAX_NODES:
                raise BadInput(source, _line(node), f"aliases expand this document beyond {MAX_NODES} nodes")
            continue
        if key in size:
            continue
        if key in open_:
            raise BadInput(source, _line(node), "a recursive alias (a node that contains itself)")
        if isinstance(node, yaml.MappingNode):
            seen: dict[str, yaml.Node] = {}
            for k, _ in node.value:
                if k.tag not in (TEXT_TAG, MERGE_TAG):  # 0E0: or 1: is a number, [a]: a list; names are text
                    shown = k.value[:60] if isinstance(k, yaml.ScalarNode) else k.tag.rsplit(":", 1)[-1]
                    raise BadInput(source, _line(k), f"a field name must be text, got {shown!r} (quote it)")
                if isinstance(k, yaml.ScalarNode) and k.tag != MERGE_TAG:
                    if k.value in seen:
                        raise BadInput(source, _line(k), f"duplicate key {k.value[:60]!r} (first on "
                                                         f"{_line(seen[k.value])})")
                    seen[k.value] = k
        open_.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in _children(node))
