"""Output paths given by a user, checked before any work starts (nothing is created by the check)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from explore.core.errors import BadInput
from explore.core.user_files import check_path_name


def check_output(path: str | Path, option: str, folder: bool = False, suffixes: tuple[str, ...] = (),
                 replace: bool = True) -> Path:
    """``path`` as a place to write a file (or, with ``folder``, a folder of results); an existing file
    only with ``replace`` (the command's ``--replace``).

    BadInput when it is empty or the current folder, a folder where a file is expected (or a
    file where a folder is), has a wrong suffix, a name longer than the file system allows, or
    lies under a file or in a folder this process cannot write to (tried with a temporary
    file, which also catches read-only file systems and permissions that ``os.access`` would
    report wrongly for root). Missing parent folders are fine: they are created when written.
    """
    text = str(path)
    path = check_path_name(text, option)
    if not text.strip() or path.resolve() == Path.cwd().resolve():
        raise BadInput(option, None, "empty, or the current folder: name a file or a new folder")
    if folder and path.exists() and not path.is_dir():
        raise BadInput(option, text, "exists and is not a folder")
    if not folder and path.is_dir():
        raise BadInput(option, text, "is a folder, expected a file path")
    if suffixes and path.suffix.lower() not in suffixes:
        raise BadInput(option, text, f"expected a {' or '.join(suffixes)} file")
    if not replace and path.is_file():
        raise BadInput(option, text, "exists: use --replace to overwrite it")
    existing = path.absolute()
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir() and existing != path.absolute():
        raise BadInput(option, text, f"{existing} is a file, not a folder")
    where = existing if existing.is_dir() else existing.parent
    try:
        with tempfile.TemporaryFile(dir=where):
            pass
    except OSError as error:
        raise BadInput(option, text, f"cannot write in {where}: {error.strerror or error}") from None
    if path.exists() and not path.is_dir() and not os.access(path, os.W_OK):
        raise BadInput(option, text, "exists and cannot be written")
    return path
