"""One process of the payload registry's concurrency test (tests/project/test_registry.py).

Spawned, so kept light: it imports the registry (no torch) and nothing of the tests."""

from __future__ import annotations

from typing import Any


def add_many(db: str, key: Any, worker: int, count: int, start: Any, results: Any) -> None:
    """Wait for ``start``, add ``count`` payloads of its own, then race the others for one shared
    payload; put ``(worker, failures, won the shared payload)`` on ``results``."""
    from deepmorph.registry import PayloadRegistry

    registry = PayloadRegistry(db)
    failures: list[str] = []
    won = False
    try:
        start.wait(60)
        for i in range(count):
            try:
                registry.add(key, worker * count + i, f"https://example.com/{worker}/{i}")
            except Exception as exc:  # noqa: BLE001 - every failure is reported to the test
                failures.append(f"{type(exc).__name__}: {exc}")
        try:
            registry.add(key, 0xFFFFFF, f"https://example.com/shared/{worker}")
            won = True
        except Exception as exc:  # noqa: BLE001
            if "already stands for" not in str(exc):
                failures.append(f"{type(exc).__name__}: {exc}")
    finally:
        results.put((worker, failures, won))
