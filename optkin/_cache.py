"""A small thread-safe cache of things built once per key (models, Functions, problems)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

__all__ = ["KeyedCache"]

T = TypeVar("T")


class KeyedCache(Generic[T]):
    """``get(key, build)`` returns the cached value, calling ``build()`` once per key."""

    def __init__(self) -> None:
        self._data: dict[Hashable, T] = {}
        self._lock = threading.Lock()

    def get(self, key: Hashable, build: Callable[[], T]) -> T:
        value = self._data.get(key)
        if value is None:
            with self._lock:
                value = self._data.get(key)
                if value is None:
                    value = build()
                    self._data[key] = value
        return value

    def clear(self) -> None:
        self._data.clear()
