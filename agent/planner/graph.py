"""The merge graph of the exact search: control sequences that reach the same (position, heading) share a state.

Depends only on the control-set shape (heading offsets on the grid of eq. 48, which speeds
are equal or zero) and the horizon H, so it is built once per shape and cached per process.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

_PACK_LIMIT = 2**62  # merge-graph keys below this pack into one int64; longer tuples are compared as rows


# ----------------------------------------------------------------------------- merge graph


@dataclass(frozen=True)
class Graph:
    """Merged search graph, depends only on the control-set shape and H.

    Level h (0..H) holds states (position node, heading class); at level H states are position
    nodes. A position node is the multiset of non-zero (heading class, speed class) steps taken,
    stored as its sorted step types padded with ``len(type_g)`` (the "no step" type); ``pos_cols``
    holds the same digits column by column (H, nodes) for fast gathers. The states of a position
    node are consecutive (``node_start``, ``node_count``), states being sorted by node. The in-edge
    tables (``in_parent``, ``in_start``, ``in_count``) serve the forward values of levels 1..H-1
    and are empty at level H, where the search needs none.
    """

    child: tuple[np.ndarray, ...]
    state_pos: tuple[np.ndarray, ...]
    pos_digits: tuple[np.ndarray, ...]
    pos_cols: tuple[np.ndarray, ...]
    in_parent: tuple[np.ndarray, ...]
    in_start: tuple[np.ndarray, ...]
    in_count: tuple[np.ndarray, ...]
    node_start: tuple[np.ndarray, ...]
    node_count: tuple[np.ndarray, ...]
    type_g: np.ndarray
    type_speed: np.ndarray


def _offsets(counts: np.ndarray) -> np.ndarray:
    """Start offsets (int64) of consecutive blocks of the given sizes."""
    out = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(counts[:-1], out=out[1:])
    return out


def _distinct32(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct values of int64 ``keys`` and each key's index among them (int32, shaped like ``keys``)."""
    uniq, inverse = np.unique(keys, return_inverse=True)
    return uniq, inverse.reshape(keys.shape).astype(np.int32)


def _turned(par_pos: np.ndarray, gcls: np.ndarray, n_pos: int, n_g: int, wrap: int, shifts: list[int]) -> np.ndarray:
    """(heading class, position) table, True where a state of the position turns to the heading class.

    Without wrap the table is shifted, not clipped: no reachable heading class leaves the range.
    """
    here = np.zeros((n_g, n_pos), dtype=bool)
    here.reshape(-1)[gcls * n_pos + par_pos] = True
    out = np.zeros_like(here)
    for mv in shifts:
        if wrap:
            r = mv % wrap
            out[r:] |= here[: n_g - r]
            out[:r] |= here[n_g - r :]
        else:
            lo, hi = max(mv, 0), n_g + min(mv, 0)
            out[lo:hi] |= here[lo - mv : hi - mv]
    return out


def _inserted(cols: np.ndarray, parent: np.ndarray, t: np.ndarray, filled: int, pad: int) -> np.ndarray:
    """Columns (H, n) of the positions ``parent`` of ``cols`` (``filled`` steps at most) with the type t inserted.

    Digit j of a sorted row with t inserted is max(row[j - 1], min(row[j], t)).
    """
    out = np.empty((cols.shape[0], parent.size), dtype=cols.dtype)
    prev = cols[0][parent]
    np.minimum(prev, t, out=out[0])
    for j in range(1, filled + 1):
        cur = cols[j][parent]
        np.maximum(prev, np.minimum(cur, t), out=out[j])
        prev = cur
    out[filled + 1 :] = pad
    return out


def _grow(
    cols: np.ndarray,
    codes: np.ndarray,
    turned: np.ndarray,
    labels: np.ndarray,
    pad: int,
    has_pad: bool,
    filled: int,
    weight: np.ndarray,
    packed: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Child positions of one level: digit columns, packed keys (sorted; unpacked: ``codes``) and lookup.

    ``cols`` (H, positions) holds the parent positions' digits (at most ``filled`` steps, padded
    with the label ``pad`` of "no step"), ``codes`` their packed keys. The pairs are the moving
    types ``labels[s, i]`` of every (heading row i, position) of ``turned`` and, if ``has_pad``,
    "no step" (the child is the parent). The child of position p with speed s and heading row i
    lands at slot ``(s * rows + i) * positions + p`` of the int32 lookup, "no step" at slot
    ``n_s * rows * positions + p`` (other entries are undefined).
    """
    horizon, n_pos = cols.shape
    n_s, n_g = labels.shape
    at_turned = np.flatnonzero(turned)
    per_g = np.count_nonzero(turned, axis=1)
    n_sub = at_turned.size
    n_moving = n_sub * n_s
    n = n_moving + (n_pos if has_pad else 0)
    tt = np.empty(n, dtype=cols.dtype)
    for s in range(n_s):
        tt[s * n_sub : (s + 1) * n_sub] = np.repeat(labels[s], per_g)
    tt[n_moving:] = pad
    if packed:
        pm = at_turned - np.repeat(np.arange(n_g, dtype=np.int64) * n_pos, per_g)
        uniq, rep, lookup = _pair_keys(cols, codes, at_turned, pm, tt, labels, filled, weight)
        row, parent = np.divmod(rep, n_pos)
        return _inserted(cols, parent, np.append(labels, pad).astype(cols.dtype)[row], filled, pad), uniq, lookup
    slots = _pair_slots(at_turned, n_s * n_g * n_pos, n_pos, n_s, has_pad)
    rows = cols.T[slots % n_pos]
    rows[:, filled] = tt
    rows.sort(axis=1)
    rows, inverse = np.unique(rows, axis=0, return_inverse=True)
    lookup = np.empty((n_s * n_g + 1) * n_pos, dtype=np.int32)
    lookup[slots] = inverse.reshape(-1)
    return np.ascontiguousarray(rows.T), codes, lookup


def _pair_slots(at_turned: np.ndarray, pad_slot: int, n_pos: int, n_s: int, has_pad: bool) -> np.ndarray:
    """Lookup slots of the pairs of :func:`_grow`, in pair order (speed blocks, then "no step")."""
    blocks = [at_turned + s * (pad_slot // n_s) for s in range(n_s)]
    if has_pad:
        blocks.append(np.arange(pad_slot, pad_slot + n_pos, dtype=np.int64))
    return np.concatenate(blocks)


def _pair_keys(
    cols: np.ndarray,
    codes: np.ndarray,
    at_turned: np.ndarray,
    pm: np.ndarray,
    tt: np.ndarray,
    labels: np.ndarray,
    filled: int,
    weight: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sorted distinct packed keys of the pairs of :func:`_grow`, the lookup slot of one pair of each, the lookup.

    A pair's key is that of its parent with the type inserted at its rank among the parent's steps;
    ``np.unique`` keeps the first pair of each key, the one with the lowest slot.
    """
    horizon, n_pos = cols.shape
    n_s, n_g = labels.shape
    n_sub = pm.size
    n_moving = n_sub * n_s
    n = tt.size
    pad_slot = n_s * n_g * n_pos
    # rank (s, i, p): steps of position p below type labels[s, i]; keyed (p, k): key of p with digit k left free
    rank = np.zeros((n_s, n_g, n_pos), dtype=np.uint8 if horizon < 256 else np.int64)
    below = labels.astype(cols.dtype)[:, :, None]
    for j in range(filled):
        rank += cols[j] < below
    keyed = np.zeros((horizon, n_pos), dtype=np.int64)
    for j in range(horizon - 1):
        keyed[j + 1 :] += cols[j] * weight[j]
        keyed[: j + 1] += cols[j] * weight[j + 1]
    keyed = np.ascontiguousarray(keyed.T)
    tagged = np.empty(n, dtype=np.int64)
    flat_rank = rank.reshape(-1)
    at_row = pm * horizon
    for s in range(n_s):
        blk = slice(s * n_sub, (s + 1) * n_sub)
        k = flat_rank[s * n_g * n_pos :][at_turned]
        tagged[blk] = keyed.reshape(-1)[at_row + k]
        k = weight[k]
        k *= tt[blk]
        tagged[blk] += k
    tagged[n_moving:] = codes[: n - n_moving]
    lookup = np.empty(pad_slot + n_pos, dtype=np.int32)
    slots = _pair_slots(at_turned, pad_slot, n_pos, n_s, n > n_moving)
    uniq, rep, inverse = np.unique(tagged, return_index=True, return_inverse=True)
    lookup[slots] = inverse.reshape(-1)
    return uniq, slots[rep], lookup


def _children(lookup: np.ndarray, slots: np.ndarray, gcls: np.ndarray, par_pos: np.ndarray) -> np.ndarray:
    """Child table (states, controls) int32: ``lookup[slots[gcls] + par_pos]``."""
    return lookup[slots[gcls] + par_pos[:, None]]


@lru_cache(maxsize=8)
def merge_graph(m: tuple[int, ...], wrap: int, speed_class: tuple[int, ...], horizon: int) -> Graph:
    """Build the merge graph for heading offsets m (grid units), wrap modulus (0: none), speed classes, H.

    A position node is keyed by the sorted tuple of its non-zero step types (heading class, speed
    class), padded to H entries; a state by that tuple and its heading class. Step types are
    labelled in order among the types some level can take, "no step" last. Exact integer keys,
    level by level: a child position depends only on (parent position, new step type), so each
    distinct such pair (the parent's heading classes turned by every distinct offset, times the
    speed classes, plus "no step") is keyed once, its sorted tuple packed into one int64 (mixed
    radix, integer order = lexicographic order; tuples too long to pack are compared as rows); a
    (position, type) lookup table then gives every state's child positions. Memoised per process,
    so all agents of a process share the graph of a control-set shape.
    """
    n_speed = len(speed_class)
    n_u = len(m) * n_speed
    moving_ids = sorted({c for c in speed_class if c >= 0})
    n_s = max(len(moving_ids), 1)
    dm = np.repeat(np.asarray(m, dtype=np.int64), n_speed)
    si = np.tile(np.array([moving_ids.index(c) if c >= 0 else -1 for c in speed_class], dtype=np.int64), len(m))
    g_off = 0 if wrap else horizon * max(abs(v) for v in m)
    n_g = wrap if wrap else 2 * g_off + 1
    g_next = np.arange(n_g, dtype=np.int64)[:, None] + dm[None, :]
    if wrap:
        g_next %= wrap
    else:
        g_next = np.clip(g_next, 0, n_g - 1)  # shifted by g_off; |g| <= h max|m| <= g_off at every reachable level
    reach = np.zeros(n_g, dtype=bool)
    reach[g_off] = True
    g_used = np.zeros(n_g, dtype=bool)
    for _ in range(horizon):
        turn = np.zeros(n_g, dtype=bool)
        turn[g_next[reach]] = True
        reach = turn
        g_used |= reach
    headings = np.flatnonzero(g_used)
    n_h = headings.size
    compact = np.zeros(n_g, dtype=np.int64)
    compact[headings] = np.arange(n_h)
    moved = headings if moving_ids else headings[:0]
    types = (moved[:, None] * n_s + np.arange(n_s)).reshape(-1)
    pad = types.size
    base = pad + 1
    labels = np.arange(moved.size, dtype=np.int32)[None, :] * n_s + np.arange(n_s, dtype=np.int32)[:, None]
    packed = base**horizon < _PACK_LIMIT
    weight = np.array([base ** (horizon - 1 - j) if packed else 0 for j in range(horizon)], dtype=np.int64)
    cols = np.full((horizon, 1), pad, dtype=np.int32)
    codes = np.array([pad * int(np.sum(weight))], dtype=np.int64)
    gcls = np.full(1, g_off, dtype=np.int64)
    par_pos = np.zeros(1, dtype=np.int64)
    child_l: list[np.ndarray] = [np.zeros((0, n_u), np.int32)]
    state_pos_l: list[np.ndarray] = [np.zeros(1, np.int32)]
    cols_l: list[np.ndarray] = [cols]
    in_parent_l: list[np.ndarray] = [np.zeros(0, np.int32)]
    in_start_l: list[np.ndarray] = [np.zeros(0, np.int64)]
    in_count_l: list[np.ndarray] = [np.zeros(0, np.int64)]
    node_start_l: list[np.ndarray] = [np.zeros(1, np.int64)]
    node_count_l: list[np.ndarray] = [np.ones(1, np.int64)]
    type_slot = np.where(si >= 0, si * moved.size + compact[g_next], n_s * moved.size)
    h_next = compact[g_next]
    shifts = sorted(set(m)) if moving_ids else []
    for h in range(1, horizon + 1):
        n_prev = cols.shape[1]
        turned = _turned(par_pos, gcls, n_prev, n_g, wrap, shifts)[moved]
        cols, codes, lookup = _grow(cols, codes, turned, labels, pad, bool(np.any(si < 0)), h - 1, weight, packed)
        cols_l.append(cols)
        n_pos = cols.shape[1]
        child_pos = _children(lookup, type_slot * n_prev, gcls, par_pos)
        del lookup
        if h == horizon:
            child_l.append(child_pos)
            state_pos = np.arange(n_pos, dtype=np.int64)
            per_node = np.ones(n_pos, dtype=np.int64)
            in_parent_l.append(np.zeros(0, np.int32))
            in_start_l.append(np.zeros(0, np.int64))
            in_count_l.append(np.zeros(0, np.int64))
        else:
            keys = child_pos.astype(np.int64)
            keys *= n_h
            keys += h_next[gcls]
            states, child = _distinct32(keys)
            del keys
            state_pos, gcls = np.divmod(states, n_h)
            gcls = headings[gcls]
            par_pos = state_pos
            counts = np.bincount(child.reshape(-1), minlength=states.size).astype(np.int64)
            per_node = np.bincount(state_pos, minlength=n_pos).astype(np.int64)
            child_l.append(child)
            order = np.argsort(child.reshape(-1), kind="stable")
            order //= n_u
            in_parent_l.append(order.astype(np.int32))
            in_start_l.append(_offsets(counts))
            in_count_l.append(counts)
        state_pos_l.append(state_pos.astype(np.int32))
        node_start_l.append(_offsets(per_node))
        node_count_l.append(per_node)
    return Graph(
        child=tuple(child_l),
        state_pos=tuple(state_pos_l),
        pos_digits=tuple(np.ascontiguousarray(c.T) for c in cols_l),
        pos_cols=tuple(cols_l),
        in_parent=tuple(in_parent_l),
        in_start=tuple(in_start_l),
        in_count=tuple(in_count_l),
        node_start=tuple(node_start_l),
        node_count=tuple(node_count_l),
        type_g=types // n_s - g_off,
        type_speed=np.array(moving_ids, dtype=np.int64)[types % n_s] if moving_ids else np.zeros(0, np.int64),
    )
