"""The wire contract: every message of the swarm, and (re-exported from :mod:`contract.keys`) every key.

One home for the wire. Key expressions are functions of the AUV id
under a prefix (default ``auvswarm``). Every message is a frozen dataclass
carrying ``version`` (:data:`SCHEMA_VERSION`), ``t_s`` (sim time, s) and
``source`` (the sending component: ``"auv/2"``, ``"world"``, ``"channel"``).
:func:`encode` packs a message as a msgpack array ``[tag, version, t_s, source,
<fields in declaration order>]``; :func:`decode` validates everything it reads
and raises :class:`DecodeError`, and nothing else, on any malformed input.

Field constraints are declared once, in the annotations (``Annotated`` ranges,
length caps and choices, :mod:`contract.schema`); the encoder and the decoder share
the same checks, one check object per message field.
Frames: positions are metres in the inertial (x east, y north) frame, headings
and bearings are radians from +x, counter-clockwise.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Annotated, Any, get_type_hints

import msgpack

from auv_swarm.contract.keys import (  # noqa: F401  the keys, re-exported: wire.modem_tx(3) etc.
    KEY_TABLE,
    MAX_AUV_ID,
    PREFIX,
    KeyRow,
    all_central_plans,
    all_commands,
    all_liveliness,
    all_modem_rx,
    all_modem_tx,
    all_sensors,
    all_telemetry,
    central_plan,
    channel_done,
    channel_events,
    channel_stats,
    channel_tick,
    clock,
    command,
    faults_injected,
    format_key_table,
    interface_rows,
    key_table,
    liveliness,
    liveliness_component,
    liveliness_session,
    modem_rx,
    modem_tx,
    nav,
    parse_auv_id,
    parse_liveliness,
    sensor,
    telemetry,
    truth,
    world_events,
)
from auv_swarm.contract.params import MAX_HORIZON
from auv_swarm.contract.schema import (  # noqa: F401  MAX_PAYLOAD_BYTES re-exported: wire.MAX_PAYLOAD_BYTES
    INT64_MAX,
    MAX_ARRAY,
    MAX_PAYLOAD_BYTES,
    Checker,
    Distinct,
    MaxLen,
    OneOf,
    Range,
    checker,
    short_repr,
)

SCHEMA_VERSION = 1
MAX_MESSAGE_BYTES = 262144
_MAX_STR = 4096


class DecodeError(ValueError):
    """Bytes that are not a valid message of the expected type and schema version."""


AuvId = Annotated[int, Range(0, MAX_AUV_ID)]
AuvIdOrNone = Annotated[int, Range(-1, MAX_AUV_ID)]
Tick = Annotated[int, Range(0, INT64_MAX)]
Count = Annotated[int, Range(0, INT64_MAX)]
SimTime = Annotated[float, Range(0.0, None)]
NonNegative = Annotated[float, Range(0.0, None)]
Name = Annotated[str, MaxLen(64)]
Label = Annotated[str, MaxLen(128)]
Reason = Annotated[str, MaxLen(256)]
Text = Annotated[str, MaxLen(1024)]
Payload = Annotated[bytes, MaxLen(MAX_PAYLOAD_BYTES)]
AliveIds = Annotated[tuple[AuvId, ...], MaxLen(MAX_AUV_ID + 1), Distinct()]
XY = tuple[float, float]


@dataclass(frozen=True)
class Message:
    """Fields common to every message: sim time ``t_s`` (s), sender ``source``, schema ``version``."""

    t_s: SimTime = field(kw_only=True)
    source: Name = field(kw_only=True)
    version: int = field(default=SCHEMA_VERSION, kw_only=True)


@dataclass(frozen=True)
class Clock(Message):
    """World -> everyone, once per tick: the tick index and the ids of the AUVs still alive."""

    tick: Tick
    alive: AliveIds


@dataclass(frozen=True)
class Nav(Message):
    """World -> AUV: its navigation at the tick, the pose it believes it has (x, y m; theta rad; u m/s; r rad/s).

    The pose is dead-reckoned (``[navigation]``, docs/navigation.md): the true one under perfect navigation.

    ``rx_expected`` is how many :class:`ModemRx` the channel delivered to this AUV
    for this tick; the agent waits for all of them before it replies (lockstep).
    """

    tick: Tick
    auv: AuvId
    x: float
    y: float
    theta: float
    u: float
    r: float
    rx_expected: Count


@dataclass(frozen=True)
class Sensor(Message):
    """World -> AUV: the DoA bearing of the source (eq. 2, rad), or None when there is no measurement.

    Under ``ocean.model = "physical"``, at a measurement: ``sigma_rad`` the bearing's noise std (rad) and
    ``snr_db`` the source's SNR at the AUV (dB), also when the detection was missed (bearing None).
    """

    tick: Tick
    auv: AuvId
    bearing_rad: float | None
    sigma_rad: NonNegative | None = None
    snr_db: float | None = None


@dataclass(frozen=True)
class Command(Message):
    """AUV -> world: the agent's reply for the tick (u m/s, r rad/s) and how many modem tx it published."""

    tick: Tick
    auv: AuvId
    u: float
    r: float
    tx_count: Count


@dataclass(frozen=True)
class ModemTx(Message):
    """AUV -> channel: one acoustic packet (``payload`` is an encoded acoustic payload, at most 64 KiB)."""

    tick: Tick
    auv: AuvId
    seq: Count
    payload: Payload


@dataclass(frozen=True)
class ModemRx(Message):
    """Channel -> AUV ``auv`` (the recipient): a packet from ``sender``, sent at ``t_sent``, heard at ``t_arrival`` (s)."""

    tick: Tick
    auv: AuvId
    sender: AuvId
    seq: Count
    payload: Payload
    t_sent: SimTime
    t_arrival: SimTime
    snr_db: float


@dataclass(frozen=True)
class ChannelTick(Message):
    """World -> channel: process this tick (transmissions expected per AUV, true positions in m).

    ``sessions``: the bus session each AUV's frames must come from (the one the world bound it to; an AUV not
    listed, as on a bus without sessions: any). ``refused``: the quarantined AUVs, whose frames are all refused."""

    tick: Tick
    tx_expected: Annotated[dict[AuvId, Count], MaxLen(MAX_AUV_ID + 1)]
    positions: Annotated[dict[AuvId, XY], MaxLen(MAX_AUV_ID + 1)]
    alive: AliveIds
    sessions: Annotated[dict[AuvId, Name], MaxLen(MAX_AUV_ID + 1)] = field(default_factory=dict)
    refused: AliveIds = ()


@dataclass(frozen=True)
class ChannelDone(Message):
    """Channel -> world: the tick is processed; ``rx_count`` packets were delivered to each AUV."""

    tick: Tick
    rx_count: Annotated[dict[AuvId, Count], MaxLen(MAX_AUV_ID + 1)]


@dataclass(frozen=True)
class Truth(Message):
    """World -> observers: ground truth; target (x, y m, vx, vy m/s) and agents id -> (x, y m, theta rad)."""

    tick: Tick
    target: tuple[float, float, float, float]
    agents: Annotated[dict[AuvId, tuple[float, float, float]], MaxLen(MAX_AUV_ID + 1)]
    alive: AliveIds


@dataclass(frozen=True)
class _Estimate(Message):
    """The fields :class:`Telemetry` and :class:`CentralPlan` start with: one AUV's tick and target estimate.

    ``xi`` is the target estimate (x, y m, vx, vy m/s; eq. 14), ``P`` its 4x4
    covariance row-major as reported (eq. 15, plus any model-error term: ``Estimate.reported_P``); both are zeros by convention when
    ``estimate_ok`` is False, and ``estimate_reason`` says why. All values must be finite.
    """

    tick: Tick
    auv: AuvId
    estimate_ok: bool
    estimate_reason: Reason
    xi: tuple[float, float, float, float]
    P: Annotated[tuple[float, ...], MaxLen(16, exact=True)]


@dataclass(frozen=True)
class Telemetry(_Estimate):
    """AUV -> orchestrator and recorder: estimator and planner state after the tick.

    The estimate as in :class:`_Estimate`. ``plan`` holds (heading change rad, speed m/s) per
    horizon step (eq. 39), ``waypoints`` the planned (x, y) positions (m),
    ``cost`` the optimal cost of eq. (38) and ``terms`` its named parts,
    ``plan_wall_ms`` the wall-clock planning time, ``fiedler`` lambda_2 of the
    predicted communication Laplacian (eq. 37), ``nav`` the pose (x, y m, theta rad) the AUV believes it has
    (its :class:`Nav`). All values must be finite.
    """

    plan: Annotated[tuple[tuple[float, float], ...], MaxLen(MAX_HORIZON)]
    waypoints: Annotated[tuple[XY, ...], MaxLen(MAX_HORIZON)]
    cost: float
    terms: Annotated[dict[Name, float], MaxLen(32)]
    plan_wall_ms: NonNegative
    n_measurements: Count
    planned: bool
    fiedler: float
    nav: tuple[float, float, float]


@dataclass(frozen=True)
class ChannelStats(Message):
    """Channel -> orchestrator and recorder: cumulative counters (packets sent, delivered, dropped by reason, ...)."""

    counters: Annotated[dict[Name, Count], MaxLen(256)]


@dataclass(frozen=True)
class PacketEvent(Message):
    """Channel -> orchestrator and recorder: one packet's fate, for the packet log (bits; latency s; SNR dB; drop reason)."""

    correlation_id: Label
    kind: Annotated[str, OneOf(("sent", "delivered", "dropped"))]
    sender: AuvId
    recipient: AuvIdOrNone
    bits: Count
    latency_s: NonNegative | None
    snr_db: float | None
    reason: Reason | None


WORLD_EVENT_KINDS = ("start", "end", "abort", "kill", "rejoin", "death", "hung", "resume", "duplicate_login")
"""The kinds of :class:`WorldEvent`."""


@dataclass(frozen=True)
class WorldEvent(Message):
    """World -> observers: a mission event; ``auv`` is -1 when no AUV is involved.

    ``end`` closes a complete mission; ``abort`` closes an incomplete one, its text starting with the reason
    (``channel_lost: ...``, ``interrupted: ...``). Every process ends on either. ``hung``: an AUV missed the
    tick timeout and is no longer waited for; ``resume``: it answered again. ``duplicate_login``: two different
    commands of one tick came on AUV ``auv``'s key (a second client holds its password), one event per such tick.
    """

    kind: Annotated[str, OneOf(WORLD_EVENT_KINDS)]
    auv: AuvIdOrNone
    text: Text


@dataclass(frozen=True)
class CentralPlan(_Estimate):
    """Central planner -> AUV (centralised MPC of section 3.3 only): the team's estimate and this AUV's plan.

    ``xi``/``P`` as in :class:`Telemetry` (the one estimate made from every AUV's bearings,
    without delay or loss); ``planned`` is True at the ticks where the joint plan was made,
    then ``plan`` holds this AUV's (heading change rad, speed m/s) per step, ``waypoints``
    its planned positions (m), ``cost``/``terms`` its part of eq. (38) given the others,
    ``plan_wall_ms`` the wall time of the whole joint plan and ``fiedler`` lambda_2 of the
    team's SNR Laplacian (eqs. 25-26) at the AUVs' navigated positions (:class:`Nav`).
    """

    n_measurements: Count
    planned: bool
    plan: Annotated[tuple[tuple[float, float], ...], MaxLen(MAX_HORIZON)]
    waypoints: Annotated[tuple[XY, ...], MaxLen(MAX_HORIZON)]
    cost: float
    terms: Annotated[dict[Name, float], MaxLen(32)]
    plan_wall_ms: NonNegative
    fiedler: float


@dataclass(frozen=True)
class FaultsInjected(Message):
    """Orchestrator -> world: the faults due at ``tick`` are injected (``faults``: "action target" each).

    The world publishes the truth of the first tick at or after a fault's time, then holds the clock
    there (before any AUV gets that tick's navigation) until this message for that tick arrives; only
    the orchestrator may put it (``bus.acl.acl_roles``). ``faults`` is empty when nothing could be
    injected (the target was not running).
    """

    tick: Tick
    faults: Annotated[tuple[Label, ...], MaxLen(64)]


MESSAGE_TYPES: tuple[type[Message], ...] = (
    Clock,
    Nav,
    Sensor,
    Command,
    ModemTx,
    ModemRx,
    ChannelTick,
    ChannelDone,
    Truth,
    Telemetry,
    ChannelStats,
    PacketEvent,
    WorldEvent,
    CentralPlan,
    FaultsInjected,
)


@dataclass(frozen=True)
class _Spec:
    tag: int
    cls: type[Message]
    fields: tuple[tuple[str, Checker], ...]


def _build_specs() -> tuple[dict[type[Message], _Spec], dict[int, _Spec]]:
    by_type: dict[type[Message], _Spec] = {}
    for tag, cls in enumerate(MESSAGE_TYPES, start=1):
        hints = get_type_hints(cls, include_extras=True)
        checks = tuple((f.name, checker(hints[f.name])) for f in dataclasses.fields(cls) if f.name != "version")
        by_type[cls] = _Spec(tag, cls, checks)
    return by_type, {s.tag: s for s in by_type.values()}


_BY_TYPE, _BY_TAG = _build_specs()


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, at any depth, to Python values (duck-typed: wire imports no numpy)."""
    if hasattr(value, "tolist") and hasattr(value, "dtype"):
        return value.tolist()
    if isinstance(value, dict):
        return {_plain(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def encode(msg: Message) -> bytes:
    """Pack ``msg`` as msgpack ``[tag, version, t_s, source, fields...]``.

    Raises ValueError naming the message type and field when a value violates the
    declared type or range (the same checks :func:`decode` applies).
    """
    spec = _BY_TYPE.get(type(msg))
    if spec is None:
        raise ValueError(
            f"encode: msg must be one of {', '.join(c.__name__ for c in MESSAGE_TYPES)}, got {short_repr(msg)}"
        )
    name = spec.cls.__name__
    if isinstance(msg.version, bool) or msg.version != SCHEMA_VERSION:
        raise ValueError(f"{name}.version must be {SCHEMA_VERSION}, got {short_repr(msg.version)}")
    values = [check(_plain(getattr(msg, f)), f"{name}.{f}") for f, check in spec.fields]
    return msgpack.packb([spec.tag, SCHEMA_VERSION, *values], use_bin_type=True)


def _unpack(data: Any) -> Any:
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise DecodeError(f"decode: data must be bytes, got {type(data).__name__}")
    if len(data) > MAX_MESSAGE_BYTES:
        raise DecodeError(f"decode: message of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES} bytes")
    try:
        return msgpack.unpackb(
            data,
            raw=False,
            strict_map_key=False,
            max_bin_len=MAX_PAYLOAD_BYTES,
            max_str_len=_MAX_STR,
            max_array_len=MAX_ARRAY,
            max_map_len=MAX_ARRAY,
            max_ext_len=0,
        )
    except Exception as exc:
        raise DecodeError(
            f"decode: not a valid msgpack message ({type(exc).__name__}: {short_repr(str(exc))})"
        ) from exc


def decode(data: bytes, expected: type[Message] | None = None) -> Message:
    """Decode one message; with ``expected``, only that message type is accepted.

    Raises :class:`DecodeError` (and nothing else) for anything malformed: bytes
    that are not msgpack, unknown tags, a wrong schema version or field count,
    wrong field types (a bool is not an int), non-finite or out-of-range values,
    oversized strings or payloads, or a type other than ``expected``.
    """
    if expected is not None and not (isinstance(expected, type) and expected in _BY_TYPE):
        raise DecodeError(f"decode: expected must be a message type or None, got {short_repr(expected)}")
    obj = _unpack(data)
    if not isinstance(obj, list) or len(obj) < 2:
        raise DecodeError(f"decode: a message is an array [tag, version, fields...], got {short_repr(obj)}")
    tag, version = obj[0], obj[1]
    spec = _BY_TAG.get(tag) if isinstance(tag, int) and not isinstance(tag, bool) else None
    if spec is None:
        raise DecodeError(f"decode: unknown message tag {short_repr(tag)}")
    name = spec.cls.__name__
    if expected is not None and spec.cls is not expected:
        raise DecodeError(f"decode: expected {expected.__name__}, got {name}")
    if isinstance(version, bool) or not isinstance(version, int) or version != SCHEMA_VERSION:
        raise DecodeError(f"{name}.version must be {SCHEMA_VERSION}, got {short_repr(version)}")
    if len(obj) != 2 + len(spec.fields):
        raise DecodeError(f"{name} must have {len(spec.fields)} fields, got {len(obj) - 2}")
    try:
        kwargs = {f: check(v, f"{name}.{f}") for (f, check), v in zip(spec.fields, obj[2:], strict=True)}
    except ValueError as exc:
        raise DecodeError(str(exc)) from None
    return spec.cls(**kwargs)
