"""Row buffers of the recorder: rows collected per entity and sent to rerun as columns (``rr.send_columns``
logs thousands of rows in milliseconds where one ``rr.log`` per row takes a second), and the sampled trails."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np


class Rows:
    """One entity's rows awaiting ``send_columns``: sim times (s) and the instances of each component per row."""

    def __init__(self, archetype: Any) -> None:
        self.archetype = archetype
        self.times: list[float] = []
        self.lengths: list[int] = []
        self.components: dict[str, list[Any]] = {}

    def add(self, t_s: float, **components: Sequence[Any]) -> None:
        lengths = {len(v) for v in components.values()}
        if len(lengths) != 1:
            raise ValueError(f"components of one row must have equal lengths, got {sorted(lengths)}")
        if not self.components:
            self.components = {k: [] for k in components}
        elif set(components) != set(self.components):
            raise ValueError(f"every row must give the components {sorted(self.components)}, got {sorted(components)}")
        self.times.append(float(t_s))
        self.lengths.append(lengths.pop())
        for k, v in components.items():
            self.components[k].extend(v)

    def columns(self) -> Any:
        data: dict[str, Any] = {}
        for k, v in self.components.items():
            if k in ("positions", "origins", "vectors"):
                data[k] = np.asarray(v, dtype=np.float32).reshape(-1, 2)
            elif k == "colors":
                data[k] = np.asarray(v, dtype=np.uint8).reshape(-1, 4)
            elif k in ("radii", "draw_order"):
                data[k] = np.asarray(v, dtype=np.float32)
            elif k == "strips":
                strips = [np.asarray(s, dtype=np.float32).reshape(-1, 2) for s in v]
                uniform = strips and all(len(s) == len(strips[0]) for s in strips)
                data[k] = np.stack(strips) if uniform else strips
            else:
                data[k] = list(v)
        return self.archetype.columns(**data).partition(self.lengths)

    def clear(self) -> None:
        self.times.clear()
        self.lengths.clear()
        for v in self.components.values():
            v.clear()


class Trail:
    """Past positions (m) spaced ``period_s`` apart in sim time."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.points: list[tuple[float, float]] = []
        self.last_t = -math.inf

    def update(self, t_s: float, xy: tuple[float, float]) -> list[tuple[float, float]] | None:
        """Append ``xy`` if ``period_s`` has passed since the last point and return the trail, else None."""
        if t_s - self.last_t < self.period_s - 1e-9:
            return None
        self.points.append(xy)
        self.last_t = t_s
        return list(self.points)


def nanos(times_s: Sequence[float]) -> np.ndarray:
    """Sim times (s) as a timedelta64[ns] array, rounded to the nearest ns like ``set_time`` does."""
    return np.round(np.asarray(times_s, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def finite(values: Sequence[float], where: str, n: int | None = None) -> tuple[float, ...]:
    """``values`` as floats, or ValueError naming ``where`` if the count is not ``n`` or one is not finite."""
    out = tuple(map(float, values))
    if n is not None and len(out) != n:
        raise ValueError(f"{where} must have {n} values, got {len(out)}")
    if not all(map(math.isfinite, out)):
        raise ValueError(f"{where} must be finite, got {out!r}")
    return out
