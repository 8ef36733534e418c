"""Test sinks for the in-process runner."""

from __future__ import annotations


class Keep:
    """A sink that keeps every message the in-process runner emits, in order."""

    def __init__(self) -> None:
        self.messages: list[object] = []

    def on_message(self, msg: object) -> None:
        self.messages.append(msg)
