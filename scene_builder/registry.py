"""A small registry of interchangeable backends for one task (depth, segmentation, naming, ...).

Learned models sit behind small protocols; each implementation registers a factory here with a
priority and an availability check. ``resolve`` picks the best available backend and says why,
so that ``report.json`` can record which backend answered. A real algorithm (never a stub) must be
registered as the always-available fallback of every task.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Generic, TypeVar

from scene_builder.errors import InputError
from scene_builder.model import BackendUse

T = TypeVar("T")


@dataclass(frozen=True)
class BackendEntry(Generic[T]):
    """name: registry key; priority: higher is preferred; available: returns None when usable,
    else a one-line reason why not; factory: builds the backend."""

    name: str
    priority: int
    factory: Callable[[], T]
    available: Callable[[], str | None]
    description: str = ""


class Registry(Generic[T]):
    """Backends for one task, resolved by priority and availability."""

    def __init__(self, task: str) -> None:
        self.task = task
        self._entries: dict[str, BackendEntry[T]] = {}

    def register(
        self,
        name: str,
        factory: Callable[[], T],
        *,
        priority: int = 0,
        available: Callable[[], str | None] = lambda: None,
        description: str = "",
    ) -> None:
        self._entries[name] = BackendEntry(name, priority, factory, available, description)

    def names(self) -> list[str]:
        return sorted(self._entries, key=lambda n: (-self._entries[n].priority, n))

    def entries(self) -> list[BackendEntry[T]]:
        return [self._entries[n] for n in self.names()]

    def resolve(self, preferred: str | None = None) -> tuple[T, BackendUse]:
        """Build the preferred backend (error if it is unknown or unavailable), else the highest
        priority available one. Returns the backend and a BackendUse saying why it answered."""
        if preferred is not None and preferred != "auto":
            entry = self._entries.get(preferred)
            if entry is None:
                raise InputError(f"unknown {self.task} backend '{preferred}'; choose one of: {', '.join(self.names())}")
            why_not = entry.available()
            if why_not is not None:
                raise InputError(f"{self.task} backend '{preferred}' is not available: {why_not}")
            return entry.factory(), BackendUse(self.task, entry.name, "requested")
        skipped: list[str] = []
        for entry in self.entries():
            why_not = entry.available()
            if why_not is None:
                reason = "best available" if not skipped else "; ".join(skipped)
                return entry.factory(), BackendUse(self.task, entry.name, reason)
            skipped.append(f"{entry.name}: {why_not}")
        raise InputError(f"no {self.task} backend is available ({'; '.join(skipped)})")
