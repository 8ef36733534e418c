"""Fixtures of the attack suite: the integration fixtures (real router and processes on loopback)."""

from __future__ import annotations

from tests.integration.conftest import connect, run_secret, spawner, start_router

__all__ = ["connect", "run_secret", "spawner", "start_router"]
