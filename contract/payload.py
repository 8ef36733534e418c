"""The compact acoustic payload an AUV puts on the modem (section 2.4.2, share and estimate).

The paper's message is ``[s_k^i, u_k^i, ..., u_{k+H-1}^i]`` (after eq. 43): the
sender's state and its planned control sequence (eq. 39). Share and estimate
adds the sender's new bearing measurements. At 120 bps a TDMA slot carries about
a thousand bits, so every field is quantised and bit-packed, most significant
bit first:

=====================  ====  ===========================================================
field                  bits  encoding
=====================  ====  ===========================================================
version                  4   :data:`PAYLOAD_VERSION`
sender                   8   AUV id 0..255
round                    8   decision epoch counter mod 256
t_s                     27   state time, 0.1 s steps, 0 .. 13 421 772.7 s (about 155 days)
x, y                 2 x 17  position, 1 m steps, signed: -65 536 .. 65 535 m
theta                   12   heading, 0.1 deg steps, 0 .. 359.9 deg
u_e                     10   base speed of eq. (47), 0.01 m/s steps, 0 .. 10.23 m/s
H                        4   plan length, 0 .. MAX_HORIZON (8; the field holds up to 15)
n_bearings               8   number of bearings, 0 .. 255
plan               H x (b+3) heading index (b = ceil(log2(n_headings)) bits), speed index (3 bits)
bearings          n x 40     per bearing: age 10 bits (0.1 s back from the state time,
                             <= 102.3 s), sensor offset 2 x 9 bits (1 m, signed, from the
                             state position, -256 .. 255 m), bearing 12 bits (0.1 deg);
                  (n x 46)   version 3 only: then the bearing's noise sigma, 6 bits,
                             0.1 deg x 2^(code / 6), 0.1 .. 146 deg (steps of 12 %)
padding                0..7  zero bits up to a whole byte
=====================  ====  ===========================================================

Version 2 is the payload of ``ocean.model = "paper"`` (uniform bearing noise, no sigma on the wire);
version 3 that of ``"physical"``, whose bearings each carry their own noise figure (docs/ocean.md).

Bearing times and sensor positions are quantised on the absolute 0.1 s and 1 m
grids before the offsets are taken, so every decoded quantity is within half a
step of the original. A bearing whose age or sensor offset does not fit its
field is dropped and counted; when the bearings do not fit the bit budget the
oldest are dropped first and counted. Decoded angles lie in (-pi, pi].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from auv_swarm.contract.params import MAX_HORIZON
from auv_swarm.contract.wire import DecodeError

PAYLOAD_VERSION = 2
PAYLOAD_VERSION_SIGMA = 3
"""The version whose bearings carry a noise sigma (``ocean.model = "physical"``)."""
_TIME_PER_S = 10
_ANGLE_PER_DEG = 10
_SPEED_PER_MPS = 100
TIME_STEP_S = 1.0 / _TIME_PER_S
POSITION_STEP_M = 1.0
ANGLE_STEP_DEG = 1.0 / _ANGLE_PER_DEG
SPEED_STEP_MPS = 1.0 / _SPEED_PER_MPS
MAX_PLAN_LENGTH = MAX_HORIZON
MAX_BEARINGS = 255
MAX_N_HEADINGS = 256
N_SPEEDS = 8

_VERSION_BITS = 4
_ID_BITS = 8
_ROUND_BITS = 8
_TIME_BITS = 27
_POS_BITS = 17
_ANGLE_BITS = 12
_SPEED_BITS = 10
_H_BITS = 4
_COUNT_BITS = 8
_SPEED_INDEX_BITS = 3
_AGE_BITS = 10
_OFFSET_BITS = 9
_SIGMA_BITS = 6
_SIGMA_STEPS_PER_OCTAVE = 6
SIGMA_MIN_DEG = 0.1
FIXED_HEADER_BITS = (
    _VERSION_BITS
    + _ID_BITS
    + _ROUND_BITS
    + _TIME_BITS
    + 2 * _POS_BITS
    + _ANGLE_BITS
    + _SPEED_BITS
    + _H_BITS
    + _COUNT_BITS
)
_ANGLE_CODES = 360 * _ANGLE_PER_DEG
_MAX_T_S = ((1 << _TIME_BITS) - 1) / _TIME_PER_S
_MAX_U_E = ((1 << _SPEED_BITS) - 1) / _SPEED_PER_MPS


@dataclass(frozen=True)
class AcousticPayload:
    """One agent's broadcast: state, plan and new bearings (section 2.4.2).

    sender: AUV id. t_s: time of the state (s, sim time). x, y: position (m,
    inertial frame). theta: heading (rad from +x, counter-clockwise). u_e: the
    sender's base speed of eq. (47) (m/s). plan: H pairs (dheading_index,
    speed_index) into the shared control set of eqs. (46)-(49); speed index 0 = 0,
    1 = u_e, then the rest of :func:`auv_swarm.agent.planner.speed_set` in order, u_max last
    (3 bits: up to 8 speeds). round: decision epoch counter mod 256. bearings: the
    sender's measurements (t_s s, sensor_x m, sensor_y m, bearing_rad), eq. (2), with a fifth entry, the
    bearing's noise sigma (rad), when ``sigma`` is True: the payload is then version 3.
    """

    sender: int
    t_s: float
    x: float
    y: float
    theta: float
    u_e: float
    plan: tuple[tuple[int, int], ...]
    round: int
    bearings: tuple[tuple[float, ...], ...]
    sigma: bool = False


def _heading_index_bits(n_headings: int) -> int:
    if isinstance(n_headings, bool) or not isinstance(n_headings, int) or not 1 <= n_headings <= MAX_N_HEADINGS:
        raise ValueError(f"n_headings must be an integer in [1, {MAX_N_HEADINGS}], got {n_headings!r}")
    return (n_headings - 1).bit_length()


def header_bits(H: int, n_headings: int) -> int:
    """Bits of everything but the bearings: fixed header (115 bits) + H * (ceil(log2(n_headings)) + 3)."""
    if isinstance(H, bool) or not isinstance(H, int) or not 0 <= H <= MAX_PLAN_LENGTH:
        raise ValueError(f"H must be an integer in [0, {MAX_PLAN_LENGTH}], got {H!r}")
    return FIXED_HEADER_BITS + H * (_heading_index_bits(n_headings) + _SPEED_INDEX_BITS)


def bearing_bits(sigma: bool = False) -> int:
    """Bits per bearing: age 10 + sensor offset 2 x 9 + bearing 12 = 40; + sigma 6 = 46 in version 3."""
    return _AGE_BITS + 2 * _OFFSET_BITS + _ANGLE_BITS + (_SIGMA_BITS if sigma else 0)


def sigma_code(sigma_rad: float) -> int:
    """The 6-bit code of a bearing sigma: round(6 log2(sigma / 0.1 deg)), clamped to 0..63."""
    deg = math.degrees(sigma_rad)
    if not deg > 0.0:
        return 0
    return min(max(round(_SIGMA_STEPS_PER_OCTAVE * math.log2(deg / SIGMA_MIN_DEG)), 0), (1 << _SIGMA_BITS) - 1)


def sigma_rad(code: int) -> float:
    """The bearing sigma (rad) of a 6-bit code."""
    return math.radians(SIGMA_MIN_DEG * 2.0 ** (code / _SIGMA_STEPS_PER_OCTAVE))


def max_bearings(budget_bits: int, H: int, n_headings: int, sigma: bool = False) -> int:
    """How many bearings fit in ``budget_bits`` next to a plan of length H (whole bytes counted).

    Raises ValueError naming budget_bits when the header alone does not fit.
    """
    if isinstance(budget_bits, bool) or not isinstance(budget_bits, int) or budget_bits < 0:
        raise ValueError(f"budget_bits must be an integer >= 0, got {budget_bits!r}")
    head = header_bits(H, n_headings)
    usable = 8 * (budget_bits // 8)
    if head > usable:
        raise ValueError(
            f"budget_bits must be >= {8 * math.ceil(head / 8)} (the padded header for H={H}, "
            f"n_headings={n_headings}), got {budget_bits}"
        )
    return min(MAX_BEARINGS, (usable - head) // bearing_bits(sigma))


def slot_budget_bits(
    bit_rate_bps: float, slot_s: float, guard_s: float, max_range_m: float, sound_speed_mps: float
) -> int:
    """Bits one TDMA slot carries: floor(bit_rate * (slot - guard - max_range / sound_speed)).

    The transmission must end early enough that the farthest receiver hears it
    before the slot is over. Paper (120 bps, 14 s slot, 1 s guard, 4 km, 1500 m/s):
    1240 bits. A tolerance of 1e-6 bit absorbs floating-point rounding.
    """
    for name, value, lo in (
        ("bit_rate_bps", bit_rate_bps, 0.0),
        ("slot_s", slot_s, 0.0),
        ("sound_speed_mps", sound_speed_mps, 0.0),
    ):
        if not math.isfinite(value) or value <= lo:
            raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    for name, value in (("guard_s", guard_s), ("max_range_m", max_range_m)):
        if not math.isfinite(value) or value < 0.0:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    airtime_s = slot_s - guard_s - max_range_m / sound_speed_mps
    if airtime_s < 0.0:
        raise ValueError(
            f"slot_s must be >= guard_s + max_range_m / sound_speed_mps = {guard_s + max_range_m / sound_speed_mps:g} s, "
            f"got {slot_s!r}"
        )
    return math.floor(bit_rate_bps * airtime_s + 1e-6)


def _finite(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _code_int(name: str, value: object, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def _angle_code(rad: float) -> int:
    return round(math.degrees(math.fmod(rad, math.tau)) * _ANGLE_PER_DEG) % _ANGLE_CODES


def _angle_rad(code: int) -> float:
    deg = code / _ANGLE_PER_DEG
    return math.radians(deg - 360.0 if deg > 180.0 else deg)


class _BitWriter:
    def __init__(self) -> None:
        self.value = 0
        self.nbits = 0

    def put(self, code: int, nbits: int) -> None:
        self.value = (self.value << nbits) | (code & ((1 << nbits) - 1))
        self.nbits += nbits

    def to_bytes(self) -> bytes:
        pad = -self.nbits % 8
        return (self.value << pad).to_bytes((self.nbits + pad) // 8, "big")


class _BitReader:
    def __init__(self, data: bytes) -> None:
        self.value = int.from_bytes(data, "big")
        self.total = 8 * len(data)
        self.pos = 0

    def get(self, nbits: int) -> int:
        if self.pos + nbits > self.total:
            raise DecodeError(f"acoustic payload: truncated at bit {self.pos} of {self.total}")
        self.pos += nbits
        return (self.value >> (self.total - self.pos)) & ((1 << nbits) - 1)

    def get_signed(self, nbits: int) -> int:
        code = self.get(nbits)
        return code - (1 << nbits) if code >> (nbits - 1) else code


def _quantised_bearings(
    p: AcousticPayload, tq: int, xq: int, yq: int, sigma: bool = False
) -> tuple[list[tuple[int, int, int, int, float, int]], int]:
    """(age, dx, dy, bearing code, t_s, sigma code) per representable bearing, and the count of unrepresentable
    ones; bearings have 4 entries, 5 with ``sigma`` (the last the sigma in rad)."""
    if not isinstance(p.bearings, (list, tuple)):
        raise ValueError(f"bearings must be a tuple of (t_s, sensor_x, sensor_y, bearing_rad), got {p.bearings!r}")
    kept: list[tuple[int, int, int, int, float, int]] = []
    width = 5 if sigma else 4
    dropped = 0
    off_lo, off_hi = -(1 << (_OFFSET_BITS - 1)), (1 << (_OFFSET_BITS - 1)) - 1
    for i, b in enumerate(p.bearings):
        if not isinstance(b, (list, tuple)) or len(b) != width:
            what = "(t_s, sensor_x, sensor_y, bearing_rad" + (", sigma_rad)" if sigma else ")")
            raise ValueError(f"bearings[{i}] must be {what}, got {b!r}")
        t, sx, sy, bearing = (_finite(f"bearings[{i}][{k}]", v) for k, v in enumerate(b[:4]))
        code = sigma_code(_finite(f"bearings[{i}][4]", b[4])) if sigma else 0
        if not 0.0 <= t <= p.t_s + TIME_STEP_S or tq - round(t * _TIME_PER_S) < 0:
            raise ValueError(f"bearings[{i}] t_s must be in [0, t_s = {p.t_s!r}] s, got {t!r}")
        age = tq - round(t * _TIME_PER_S)
        dx, dy = round(sx) - xq, round(sy) - yq
        if age >= (1 << _AGE_BITS) or not (off_lo <= dx <= off_hi and off_lo <= dy <= off_hi):
            dropped += 1
            continue
        kept.append((age, dx, dy, _angle_code(bearing), t, code))
    return kept, dropped


def encode_payload(p: AcousticPayload, budget_bits: int, n_headings: int) -> tuple[bytes, int]:
    """Bit-pack ``p`` into at most ``budget_bits`` (counted as whole bytes); returns (bytes, bearings dropped).
    With ``p.sigma`` version 3, each bearing with its noise sigma (6 bits); else version 2.

    Quantisation: time 0.1 s, position 1 m, angles 0.1 deg, u_e 0.01 m/s (see the
    module docstring for the layout). Bearings that do not fit (age > 102.3 s,
    sensor more than 255 m from the state position, or over the budget, oldest
    first) are dropped and counted; the kept ones stay in their given order.
    Raises ValueError naming the field for out-of-range values, and naming
    budget_bits when the header alone exceeds the budget.
    """
    hb = _heading_index_bits(n_headings)
    sender = _code_int("sender", p.sender, 0, (1 << _ID_BITS) - 1)
    epoch = _code_int("round", p.round, 0, (1 << _ROUND_BITS) - 1)
    t_s = _finite("t_s", p.t_s)
    tq = round(t_s * _TIME_PER_S) if 0.0 <= t_s <= _MAX_T_S else -1
    if not 0 <= tq < 1 << _TIME_BITS:
        raise ValueError(f"t_s must be in [0, {_MAX_T_S:.1f}] s, got {p.t_s!r}")
    pos_lo, pos_hi = -(1 << (_POS_BITS - 1)), (1 << (_POS_BITS - 1)) - 1
    xq, yq = round(_finite("x", p.x)), round(_finite("y", p.y))
    for name, q, raw in (("x", xq, p.x), ("y", yq, p.y)):
        if not pos_lo <= q <= pos_hi:
            raise ValueError(f"{name} must be in [{pos_lo}, {pos_hi}] m, got {raw!r}")
    theta_code = _angle_code(_finite("theta", p.theta))
    u_e = _finite("u_e", p.u_e)
    uq = round(u_e * _SPEED_PER_MPS) if 0.0 <= u_e <= _MAX_U_E else -1
    if not 0 <= uq < 1 << _SPEED_BITS:
        raise ValueError(f"u_e must be in [0, {_MAX_U_E:.2f}] m/s, got {p.u_e!r}")
    if not isinstance(p.plan, (list, tuple)) or len(p.plan) > MAX_PLAN_LENGTH:
        raise ValueError(f"plan must be a tuple of at most {MAX_PLAN_LENGTH} (dheading_index, speed_index) pairs")
    plan = []
    for h, step in enumerate(p.plan):
        if not isinstance(step, (list, tuple)) or len(step) != 2:
            raise ValueError(f"plan[{h}] must be a (dheading_index, speed_index) pair, got {step!r}")
        plan.append(
            (
                _code_int(f"plan[{h}] dheading_index", step[0], 0, n_headings - 1),
                _code_int(f"plan[{h}] speed_index", step[1], 0, N_SPEEDS - 1),
            )
        )
    sigma = bool(p.sigma)
    room = max_bearings(budget_bits, len(plan), n_headings, sigma)
    bearings, dropped = _quantised_bearings(p, tq, xq, yq, sigma)
    if len(bearings) > room:
        newest = sorted(range(len(bearings)), key=lambda i: (bearings[i][4], i), reverse=True)[:room]
        dropped += len(bearings) - room
        bearings = [bearings[i] for i in sorted(newest)]

    w = _BitWriter()
    w.put(PAYLOAD_VERSION_SIGMA if sigma else PAYLOAD_VERSION, _VERSION_BITS)
    w.put(sender, _ID_BITS)
    w.put(epoch, _ROUND_BITS)
    w.put(tq, _TIME_BITS)
    w.put(xq, _POS_BITS)
    w.put(yq, _POS_BITS)
    w.put(theta_code, _ANGLE_BITS)
    w.put(uq, _SPEED_BITS)
    w.put(len(plan), _H_BITS)
    w.put(len(bearings), _COUNT_BITS)
    for dheading, speed in plan:
        w.put(dheading, hb)
        w.put(speed, _SPEED_INDEX_BITS)
    for age, dx, dy, code, _, scode in bearings:
        w.put(age, _AGE_BITS)
        w.put(dx, _OFFSET_BITS)
        w.put(dy, _OFFSET_BITS)
        w.put(code, _ANGLE_BITS)
        if sigma:
            w.put(scode, _SIGMA_BITS)
    return w.to_bytes(), dropped


def decode_payload(data: bytes, n_headings: int) -> AcousticPayload:
    """Unpack a payload made by :func:`encode_payload` with the same ``n_headings``.

    Raises :class:`contract.wire.DecodeError` for anything malformed: wrong
    version, wrong length, an index outside the control set, an angle code
    >= 360 deg, a bearing time before 0, or non-zero padding. Raises ValueError
    for an invalid ``n_headings``.
    """
    hb = _heading_index_bits(n_headings)
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise DecodeError(f"acoustic payload: data must be bytes, got {type(data).__name__}")
    longest = math.ceil((header_bits(MAX_PLAN_LENGTH, n_headings) + MAX_BEARINGS * bearing_bits(True)) / 8)
    if len(data) > longest:
        raise DecodeError(f"acoustic payload: {len(data)} bytes exceeds the longest possible payload ({longest} bytes)")
    data = bytes(data)
    fixed_bytes = math.ceil(FIXED_HEADER_BITS / 8)
    if len(data) < fixed_bytes:
        raise DecodeError(f"acoustic payload: {len(data)} bytes is shorter than the {fixed_bytes}-byte header")
    head = _BitReader(data[:fixed_bytes])
    version = head.get(_VERSION_BITS)
    if version not in (PAYLOAD_VERSION, PAYLOAD_VERSION_SIGMA):
        raise DecodeError(
            f"acoustic payload: version must be {PAYLOAD_VERSION} or {PAYLOAD_VERSION_SIGMA}, got {version}"
        )
    sigma = version == PAYLOAD_VERSION_SIGMA
    head.pos = FIXED_HEADER_BITS - _H_BITS - _COUNT_BITS
    H, n = head.get(_H_BITS), head.get(_COUNT_BITS)
    if H > MAX_PLAN_LENGTH:
        raise DecodeError(f"acoustic payload: plan length {H} is over the limit {MAX_PLAN_LENGTH}")
    total_bits = header_bits(H, n_headings) + n * bearing_bits(sigma)
    if len(data) != math.ceil(total_bits / 8):
        raise DecodeError(
            f"acoustic payload: length must be {math.ceil(total_bits / 8)} bytes for H={H} and {n} bearings, "
            f"got {len(data)}"
        )

    r = _BitReader(data)
    r.get(_VERSION_BITS)
    sender = r.get(_ID_BITS)
    epoch = r.get(_ROUND_BITS)
    tq = r.get(_TIME_BITS)
    xq, yq = r.get_signed(_POS_BITS), r.get_signed(_POS_BITS)
    theta_code = r.get(_ANGLE_BITS)
    uq = r.get(_SPEED_BITS)
    r.get(_H_BITS + _COUNT_BITS)
    if theta_code >= _ANGLE_CODES:
        raise DecodeError(f"acoustic payload: theta code must be < {_ANGLE_CODES}, got {theta_code}")
    plan = []
    for h in range(H):
        dheading, speed = r.get(hb), r.get(_SPEED_INDEX_BITS)
        if dheading >= n_headings or speed >= N_SPEEDS:
            raise DecodeError(
                f"acoustic payload: plan[{h}] must index n_headings={n_headings} and {N_SPEEDS} speeds, "
                f"got ({dheading}, {speed})"
            )
        plan.append((dheading, speed))
    bearings = []
    for i in range(n):
        age, dx, dy, code = r.get(_AGE_BITS), r.get_signed(_OFFSET_BITS), r.get_signed(_OFFSET_BITS), r.get(_ANGLE_BITS)
        extra = (sigma_rad(r.get(_SIGMA_BITS)),) if sigma else ()
        if code >= _ANGLE_CODES:
            raise DecodeError(f"acoustic payload: bearings[{i}] code must be < {_ANGLE_CODES}, got {code}")
        if age > tq:
            raise DecodeError(f"acoustic payload: bearings[{i}] age {age / _TIME_PER_S:.1f} s precedes time 0")
        bearings.append(((tq - age) / _TIME_PER_S, float(xq + dx), float(yq + dy), _angle_rad(code), *extra))
    if r.get(r.total - r.pos) != 0:
        raise DecodeError("acoustic payload: padding bits must be zero")
    return AcousticPayload(
        sender=sender,
        t_s=tq / _TIME_PER_S,
        x=float(xq),
        y=float(yq),
        theta=_angle_rad(theta_code),
        u_e=uq / _SPEED_PER_MPS,
        plan=tuple(plan),
        round=epoch,
        bearings=tuple(bearings),
        sigma=sigma,
    )
