"""Behaviour-tree files: parse and validate YAML trees, resolve includes, build py_trees trees.

The format is documented in ``docs/trees.md``. Parsing yields a plain :class:`Node` tree
(no py_trees involved), so ``explore tree validate`` checks a file without building it.
Every problem is a :class:`BadInput` naming the file and the node path, e.g.
``trees/model_object.yaml: root.children[2].child: unknown behaviour 'scna' (valid: ...)``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from explore.core import BadInput, brief, check_path_name, load_yaml, valid_names, validate_params
from explore.runtime.behaviour import ExploreBehaviour
from explore.runtime.decorators import RepeatUntil
from explore.sim import repo_root

COMPOSITES = ("sequence", "selector", "parallel")
DECORATORS = (
    "retry",
    "repeat",
    "repeat_until",
    "timeout",
    "for_each",
    "inverter",
    "one_shot",
    "failure_is_success",
    "success_is_failure",
    "running_is_failure",
)
NODE_TYPES = COMPOSITES + DECORATORS + ("behaviour", "include")

# attributes each node type accepts besides its type key (whose value is the display name)
_ATTRIBUTES: dict[str, dict[str, type | tuple[type, ...]]] = {
    "sequence": {"memory": bool, "children": list},
    "selector": {"memory": bool, "children": list},
    "parallel": {"policy": str, "synchronise": bool, "children": list},
    "retry": {"attempts": int, "child": dict},
    "repeat": {"times": int, "child": dict},
    "repeat_until": {"until": str, "max_iterations": int, "on_max": str, "child": dict},
    "timeout": {"seconds": (int, float), "child": dict},
    "for_each": {"items": str, "as": str, "child": dict},
    "inverter": {"child": dict},
    "one_shot": {"on": str, "child": dict},
    "failure_is_success": {"child": dict},
    "success_is_failure": {"child": dict},
    "running_is_failure": {"child": dict},
    "behaviour": {"name": str, "params": dict},
    "include": {"name": str},
}
_REQUIRED = {
    "sequence": ("children",),
    "selector": ("children",),
    "parallel": ("children",),
    "retry": ("attempts", "child"),
    "repeat": ("times", "child"),
    "repeat_until": ("until", "child"),
    "timeout": ("seconds", "child"),
    "for_each": ("items", "as", "child"),
    "one_shot": ("child",),
}


@dataclass
class Node:
    """A parsed tree node (before py_trees)."""

    type: str
    name: str
    attrs: dict[str, Any] = field(default_factory=dict)
    children: list[Node] = field(default_factory=list)
    behaviour: str | None = None
    params: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    path: str = ""

    def walk(self):
        yield self
        for child in self.children:
            yield from child.walk()


@dataclass
class TreeFile:
    path: Path
    name: str
    description: str
    root: Node


def tree_search_path() -> list[Path]:
    paths = [Path(p) for p in os.environ.get("EXPLORE_TREES", "").split(os.pathsep) if p]
    return paths + [Path.cwd() / "trees", repo_root() / "trees"]


def find_tree(name_or_path: str | Path, relative_to: Path | None = None) -> Path:
    """Resolve a tree given as a path (absolute, or relative to an including file) or a name."""
    candidate = check_path_name(name_or_path)
    bases = ([relative_to] if relative_to else []) + [Path.cwd()]
    given = [candidate if candidate.is_absolute() else base / candidate for base in bases]
    for path in given:
        if path.is_file():
            return path.resolve()
    for folder in tree_search_path():
        for suffix in ("", ".yaml", ".yml"):
            path = folder / f"{name_or_path}{suffix}"
            if path.is_file():
                return path.resolve()
    if any(path.is_dir() for path in given):
        raise BadInput(str(name_or_path), None, "is a folder, not a tree file")
    names = ", ".join(sorted({p.stem for f in tree_search_path() for p in f.glob("*.yaml")}))
    raise BadInput(str(name_or_path), None, f"no such tree file (shipped trees: {names})")


def list_trees() -> list[Path]:
    seen: dict[str, Path] = {}
    for folder in tree_search_path():
        for path in sorted(folder.glob("*.yaml")):
            seen.setdefault(path.stem, path)
    return list(seen.values())


def load_tree(name_or_path: str | Path, registry: Any, _stack: tuple[Path, ...] = ()) -> TreeFile:
    """Parse and validate a tree file with its includes against the behaviour registry."""
    path = find_tree(name_or_path, _stack[-1].parent if _stack else None)
    if path in _stack:
        chain = " -> ".join(p.name for p in (*_stack, path))
        raise BadInput(str(_stack[-1]), "include", f"include cycle: {chain}")
    data = load_yaml(path)
    file = str(path)
    if not isinstance(data, dict):
        raise BadInput(file, None, "a tree file is a mapping with 'root' (and optional name, description)")
    unknown = sorted(set(data) - {"name", "description", "root"})
    if unknown:
        raise BadInput(file, unknown[0], "unknown field (valid: name, description, root)")
    if "root" not in data:
        raise BadInput(file, "root", "missing")
    for key in ("name", "description"):
        if data.get(key) is not None and not isinstance(data[key], str):
            raise BadInput(file, key, f"expected text, got {brief(data[key])}")
    root = _parse(data["root"], file, "root", registry, (*_stack, path))
    if not _stack:
        _check_blackboard_keys(root, registry)
    return TreeFile(path, data.get("name") or path.stem, data.get("description") or "", root)


def _parse(data: Any, file: str, where: str, registry: Any, stack: tuple[Path, ...]) -> Node:
    if not isinstance(data, dict):
        raise BadInput(file, where, f"a node is a mapping with one of {', '.join(NODE_TYPES)}")
    types = [k for k in data if k in NODE_TYPES]
    if len(types) > 1:
        raise BadInput(file, where, f"a node needs exactly one node type key; found {', '.join(types)}")
    if not types:
        found = ", ".join(brief(k) for k in list(data)[:6]) or "nothing"
        guess = valid_names(str(next(iter(data), "")), NODE_TYPES, "docs/trees.md")
        raise BadInput(file, where, f"a node needs exactly one node type key; found {found} {guess}")
    kind = types[0]
    allowed = _ATTRIBUTES[kind]
    for key in data:
        if key != kind and key not in allowed:
            valid = ", ".join(sorted(allowed)) or "none"
            raise BadInput(file, f"{where}.{key}", f"unknown attribute of a {kind} node (valid: {valid})")
    for key in _REQUIRED.get(kind, ()):
        if key not in data:
            raise BadInput(file, f"{where}.{key}", f"a {kind} node needs '{key}'")
    for key, expected in allowed.items():
        if key not in data:
            continue
        value = data[key]
        if not isinstance(value, expected) or (expected is int and isinstance(value, bool)):
            names = expected.__name__ if isinstance(expected, type) else " or ".join(t.__name__ for t in expected)
            raise BadInput(file, f"{where}.{key}", f"expected {names}, got {brief(value)}")
    if kind == "behaviour":
        behaviour = data[kind]
        if not isinstance(behaviour, str):
            raise BadInput(file, f"{where}.behaviour", "expected a behaviour name")
        info = registry.get("behaviour", behaviour, file, f"{where}.behaviour")
        params = validate_params(info.params, data.get("params"), file, f"{where}.params.")
        return Node("behaviour", str(data.get("name") or behaviour), {}, [], behaviour, params, file, where)
    if kind == "include":
        if not isinstance(data[kind], str) or not data[kind]:
            raise BadInput(file, f"{where}.include", f"expected a tree name or file, got {brief(data[kind])}")
        try:
            target = find_tree(data[kind], stack[-1].parent)
        except BadInput as error:  # name the including file and node, not only the missing name
            raise BadInput(file, f"{where}.include", f"{brief(data[kind])}: {error.message}") from None
        included = load_tree(target, registry, stack)
        node = included.root
        if data.get("name"):
            node.name = str(data["name"])
        return node
    if data[kind] is not None and not isinstance(data[kind], str):
        raise BadInput(file, f"{where}.{kind}", f"expected the node's name (text, or empty), got {brief(data[kind])}")
    name = data[kind] or kind.replace("_", " ")
    attrs = {k: v for k, v in data.items() if k not in (kind, "children", "child")}
    _check_values(kind, attrs, file, where)
    if kind in COMPOSITES:
        if not data["children"]:
            raise BadInput(file, f"{where}.children", "needs at least one child")
        children = [_parse(c, file, f"{where}.children[{i}]", registry, stack) for i, c in enumerate(data["children"])]
    else:
        if "child" not in data:
            raise BadInput(file, f"{where}.child", f"a {kind} node needs 'child'")
        children = [_parse(data["child"], file, f"{where}.child", registry, stack)]
    return Node(kind, name, attrs, children, None, {}, file, where)


def _check_blackboard_keys(root: Node, registry: Any) -> None:
    """Every key a loop reads (``until``, ``items``) or a behaviour names in a parameter
    (``key_params``, e.g. ``check_flag``'s ``key``) must be written by a behaviour of the tree or a
    ``for_each``'s ``as``: a misspelt flag would otherwise loop until its budget runs out, or a
    condition would never be met.

    Checked only when every behaviour declares what it writes (``writes`` of the base class);
    a behaviour that registers blackboard keys on its own could write anything.
    """
    written: set[str] = set()
    read: list[tuple[Node, str, str]] = []  # (node, where in it, key)
    for node in root.walk():
        if node.type == "behaviour":
            factory = registry.get("behaviour", node.behaviour).factory
            if not (isinstance(factory, type) and issubclass(factory, ExploreBehaviour)):
                return
            written.update(factory.writes)
            read += [(node, f"params.{name}", node.params[name]) for name in factory.key_params]
        else:
            if node.type == "for_each":
                written.add(node.attrs["as"])
            read += [(node, key, node.attrs[key]) for key in ("until", "items") if key in node.attrs]
    for node, where, key in read:
        if key not in written:
            raise BadInput(node.source, f"{node.path}.{where}", f"no behaviour of the tree writes "
                           f"{brief(key)} (written: {', '.join(sorted(written)) or 'nothing'})")


def _check_values(kind: str, attrs: dict[str, Any], file: str, where: str) -> None:
    if kind == "parallel" and attrs.get("policy", "success_on_all") not in ("success_on_all", "success_on_one"):
        raise BadInput(file, f"{where}.policy", "expected success_on_all or success_on_one")
    if kind == "repeat_until" and attrs.get("on_max", "success") not in ("success", "failure"):
        raise BadInput(file, f"{where}.on_max", "expected success or failure")
    if kind == "one_shot" and attrs.get("on", "completion") not in ("completion", "success"):
        raise BadInput(file, f"{where}.on", "expected completion or success")
    for key in ("until", "items", "as"):
        if key in attrs and not attrs[key].strip():
            raise BadInput(file, f"{where}.{key}", "an empty blackboard key")
    for key in ("attempts", "times", "max_iterations", "seconds"):
        if key in attrs and not (math.isfinite(attrs[key]) and attrs[key] > 0):
            raise BadInput(file, f"{where}.{key}", f"must be a positive finite number, got {attrs[key]}")


def build(node: Node, registry: Any, overrides: dict[str, dict[str, Any]] | None = None, namespace: str = ""):
    """Build the py_trees tree for a parsed node.

    ``overrides`` maps behaviour name -> parameters (from ``--set``); blackboard keys named in
    the file (``until``, ``items``, ``as``) are relative to the run's ``namespace``.
    """
    import py_trees

    overrides = overrides or {}
    if node.type == "behaviour":
        info = registry.get("behaviour", node.behaviour)
        params = dict(node.params)
        if node.behaviour in overrides:
            params.update(validate_params(info.params, overrides[node.behaviour], "--set", f"{node.behaviour}."))
        behaviour = info.factory(name=node.name, **params)
        behaviour.tree_path = node.path
        return behaviour
    children = [build(c, registry, overrides, namespace) for c in node.children]
    a = node.attrs
    d = py_trees.decorators
    if node.type == "sequence":
        return py_trees.composites.Sequence(node.name, memory=a.get("memory", True), children=children)
    if node.type == "selector":
        return py_trees.composites.Selector(node.name, memory=a.get("memory", False), children=children)
    if node.type == "parallel":
        synchronise = a.get("synchronise", True)
        policy = (
            py_trees.common.ParallelPolicy.SuccessOnOne()
            if a.get("policy") == "success_on_one"
            else py_trees.common.ParallelPolicy.SuccessOnAll(synchronise=synchronise)
        )
        return py_trees.composites.Parallel(node.name, policy=policy, children=children)
    child = children[0]
    if node.type == "retry":
        return d.Retry(node.name, child, num_failures=a["attempts"])
    if node.type == "repeat":
        return d.Repeat(node.name, child, num_success=a["times"])
    if node.type == "repeat_until":
        until = f"{namespace}/{a['until']}"
        return RepeatUntil(node.name, child, until, a.get("max_iterations", 1000), a.get("on_max", "success"))
    if node.type == "timeout":
        return d.Timeout(node.name, child, duration=float(a["seconds"]))
    if node.type == "for_each":
        return d.ForEach(node.name, child, source_key=f"{namespace}/{a['items']}", target_key=f"{namespace}/{a['as']}")
    if node.type == "inverter":
        return d.Inverter(node.name, child)
    if node.type == "one_shot":
        policy = (
            py_trees.common.OneShotPolicy.ON_SUCCESSFUL_COMPLETION
            if a.get("on") == "success"
            else py_trees.common.OneShotPolicy.ON_COMPLETION
        )
        return d.OneShot(node.name, child, policy=policy)
    if node.type == "failure_is_success":
        return d.FailureIsSuccess(node.name, child)
    if node.type == "success_is_failure":
        return d.SuccessIsFailure(node.name, child)
    if node.type == "running_is_failure":
        return d.RunningIsFailure(node.name, child)
    raise AssertionError(node.type)
