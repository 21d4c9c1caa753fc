"""The run's worker thread: long steps run there one after another while the tree keeps ticking."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any


class Worker:
    """Runs the submitted steps one after another in a daemon thread.

    A step abandoned while it runs (e.g. a ``timeout`` decorator stopped its behaviour)
    cannot be killed in Python: it finishes in its own thread and its result is dropped,
    while the steps submitted after it run in a fresh thread instead of waiting behind it.
    """

    def __init__(self, name: str = "explore-worker") -> None:
        self.name = name
        self.abandoned = 0
        self._lock = threading.Lock()
        self._queue: queue.SimpleQueue | None = None
        self._start()

    def _start(self) -> None:
        self._queue = queue.SimpleQueue()
        thread = threading.Thread(target=self._loop, args=(self._queue,), daemon=True,
                                  name=f"{self.name}-{self.abandoned}")
        thread.start()

    def _loop(self, own: queue.SimpleQueue) -> None:
        while True:
            item = own.get()
            with self._lock:
                if own is not self._queue:  # retired after an abandoned step: hand the work over
                    if item is not None:
                        self._queue.put(item)
                    return
            if item is None:
                return
            future, fn = item
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn()
            except BaseException as error:  # noqa: BLE001 - delivered to whoever polls the future
                future.set_exception(error)
            else:
                future.set_result(result)

    def submit(self, fn: Callable[[], Any]) -> Future:
        future: Future = Future()
        with self._lock:
            self._queue.put((future, fn))
        return future

    def abandon(self, future: Future) -> bool:
        """Drop a step: cancel it if it has not started; else move later steps to a fresh thread.

        Returns True if the step was still running (it goes on in the background).
        """
        if future.cancel() or future.done():
            return False
        with self._lock:
            old = self._queue
            self.abandoned += 1
            self._start()
            while True:
                try:
                    self._queue.put(old.get_nowait())
                except queue.Empty:
                    break
            old.put(None)
        return True

    def close(self) -> None:
        with self._lock:
            while True:
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    break
                if item is not None:
                    item[0].cancel()
            self._queue.put(None)
