"""Keep what native libraries print (Open3D, pybullet's ``b3Error``, Ray's C++ core) off the
terminal, so that an error is one clean line and nothing stands before it.

These libraries write to the process' file descriptors 1 and 2 from C++, below Python's
``sys.stdout`` / ``sys.stderr``; only a redirection of the descriptors themselves silences them.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass


@dataclass
class Captured:
    """What the native code printed inside :func:`captured_output` (filled when the block ends)."""

    text: str = ""


def _flush_c_stdio() -> None:
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def captured_output(stdout: bool = False) -> Iterator[Captured]:
    """Redirect file descriptor 2 (and 1 with ``stdout``) into a temporary file for the block.

    The captured text is available as ``.text`` after the block; nothing of it reaches the
    terminal. Python-level writes to ``sys.stderr`` inside the block are captured too.
    """
    captured = Captured()
    fds = [2, 1] if stdout else [2]
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    saved = {fd: os.dup(fd) for fd in fds}
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            for fd in fds:
                os.dup2(sink.fileno(), fd)
            yield captured
        finally:
            for stream in (sys.stdout, sys.stderr):
                with contextlib.suppress(Exception):
                    stream.flush()
            _flush_c_stdio()  # what C code printf'ed sits in stdio's buffers: into the sink with it
            for fd, copy in saved.items():
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            captured.text = sink.read().decode("utf-8", errors="replace")
