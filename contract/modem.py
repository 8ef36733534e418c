"""The modem under ``ocean.model = "physical"``: link SNR, packet-error curves, bursty loss, eqs. (22)-(26).

Units: ranges in metres, levels in dB, probabilities in [0, 1]. Pure: no I/O, no randomness (uniform variates
are arguments).

- Link SNR of eq. (22) with a computed TL and noise: rho = SL - TL(d) - NL_band + DI, NL integrated over the
  modem's band (``contract.propagation``).
- Delivery of one modem frame: a logistic curve in SNR (dB) through the 10 % and 90 % delivery points of the
  WHOI Micro-Modem packet-error tables that ros_acomms simulates with (``sim_packet_performance_node.py``: frame
  error 1 -> 0 over -7.96...-6.01 dB at rate 1, -2.92...0.00 dB at rate 3, 3.10...6.02 dB at rate 5). A payload
  of L bits takes ceil(L / frame bits) frames and arrives only if every frame decodes: P = p_frame^n_frames.
- Bursty loss: a two-state Gilbert-Elliott chain per directed link, stepped once per frame.
- Connectivity (eqs. 25-26): edge weight rho / rho_M where rho >= DT and rho > 0 dB, with DT the SNR at which
  one frame gets through half the time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class ModemCurve:
    """One modem rate: SNR (dB) of 10 % and 90 % frame delivery, and the frame length (bits)."""

    name: str
    snr10_db: float
    snr90_db: float
    frame_bits: int

    @property
    def snr50_db(self) -> float:
        """SNR (dB) at which a frame is delivered half the time: the centre of the logistic curve."""
        return 0.5 * (self.snr10_db + self.snr90_db)

    @property
    def width_db(self) -> float:
        """Logistic scale (dB): the 10 % -> 90 % span is 2 ln 9 widths."""
        return (self.snr90_db - self.snr10_db) / (2.0 * math.log(9.0))

    def frame_delivery(self, snr_db: ArrayLike) -> np.ndarray:
        """Probability that one frame heard at ``snr_db`` decodes: 1 / (1 + exp(-(snr - snr50) / width))."""
        z = (np.asarray(snr_db, dtype=float) - self.snr50_db) / self.width_db
        return 0.5 * (1.0 + np.tanh(0.5 * z))

    def frames(self, bits: int) -> int:
        """Modem frames a payload of ``bits`` takes (at least one)."""
        return max(1, -(-int(bits) // self.frame_bits))

    def delivery(self, snr_db: ArrayLike, bits: int) -> np.ndarray:
        """Probability that a payload of ``bits`` decodes: every one of its frames must."""
        return self.frame_delivery(snr_db) ** self.frames(bits)


MODEMS = {
    # 10 % / 90 % delivery points by linear interpolation of the ros_acomms frame-error tables (docs/ocean.md);
    # frame sizes from the Micro-Modem rate table: rate 1 frames of 64 bytes, rates 3 and 5 of 256 bytes
    "micromodem-rate1": ModemCurve("micromodem-rate1", -7.539, -6.658, 512),
    "micromodem-rate3": ModemCurve("micromodem-rate3", -2.260, -0.689, 2048),
    "micromodem-rate5": ModemCurve("micromodem-rate5", 3.253, 4.850, 2048),
}
"""The modem rates ``ocean.modem`` names."""


class GilbertElliott:
    """Two-state bursty loss (Gilbert 1960, Elliott 1963) of one directed link, stepped once per frame.

    From the good state the link goes bad with probability ``p_gb``, from the bad state it recovers with
    ``p_bg``; a frame sent in the bad state is lost with probability ``loss``. The first frame starts from the
    stationary law (bad with pi = p_gb / (p_gb + p_bg)). Long-run loss pi * loss; mean burst 1 / p_bg frames.
    """

    def __init__(self, p_gb: float, p_bg: float, loss: float) -> None:
        for name, v in (("p_gb", p_gb), ("loss", loss)):
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {v!r}")
        if not 0.0 < p_bg <= 1.0:
            raise ValueError(f"p_bg must be in (0, 1], got {p_bg!r}")
        self.p_gb, self.p_bg, self.loss = float(p_gb), float(p_bg), float(loss)
        self.bad: bool | None = None

    @property
    def stationary_bad(self) -> float:
        """Long-run share of frames sent in the bad state."""
        return self.p_gb / (self.p_gb + self.p_bg)

    def step(self, u_state: float, u_loss: float) -> bool:
        """Advance one frame with two uniform variates in [0, 1); True if the frame is lost."""
        if self.bad is None:
            self.bad = u_state < self.stationary_bad
        elif self.bad:
            self.bad = u_state >= self.p_bg
        else:
            self.bad = u_state < self.p_gb
        return self.bad and u_loss < self.loss


class LinkModel:
    """The modem link of a physical ocean: SNR (eq. 22), delivery, delay and the edge weights of eqs. (25)-(26).

    ``tl`` is a TL model of range (``contract.propagation.TLCurve`` or ``PracticalTL``) for a source and a
    receiver both at the AUVs' depth; ``source_level_db``, ``noise_level_db`` (in the modem band),
    ``directivity_index_db`` in dB; ``sound_speed_mps`` the profile's mean (propagation delay);
    ``snr_max_db`` the normaliser rho_M of eq. (26) (0: SL - NL + DI, the SNR at TL = 0).
    """

    def __init__(
        self,
        tl: object,
        curve: ModemCurve,
        source_level_db: float,
        noise_level_db: float,
        directivity_index_db: float,
        sound_speed_mps: float,
        snr_max_db: float = 0.0,
    ) -> None:
        self.tl = tl
        self.curve = curve
        self.noise_level_db = float(noise_level_db)
        self.snr_at_tl0_db = float(source_level_db - noise_level_db + directivity_index_db)
        self.sound_speed_mps = float(sound_speed_mps)
        self.threshold_db = curve.snr50_db
        rho_m = float(snr_max_db) if snr_max_db > 0.0 else self.snr_at_tl0_db
        self.rho_max_db = rho_m
        self._inv_rho_max = 1.0 / rho_m if rho_m > 0.0 else 1.0

    def snr_db(self, range_m: ArrayLike) -> np.ndarray:
        """Link SNR rho (dB) of eq. (22) at ``range_m`` (m): SL - TL(d) - NL + DI."""
        return self.snr_at_tl0_db - self.tl(range_m)

    def delivery(self, snr_db: float, bits: int) -> float:
        """Probability that a frame of ``bits`` heard at ``snr_db`` decodes (:class:`ModemCurve`)."""
        return float(self.curve.delivery(snr_db, bits))

    def delay_s(self, range_m: float) -> float:
        """Propagation delay (s): range over the profile's mean sound speed."""
        return float(range_m) / self.sound_speed_mps

    def _weight(self, rho: np.ndarray) -> np.ndarray:
        off = (rho < self.threshold_db) | (rho <= 0.0)
        return np.where(off, 0.0, rho * self._inv_rho_max)

    def weight(self, range_m: ArrayLike) -> np.ndarray:
        """Normalised edge weight rho / rho_M of eqs. (25)-(26); 0 where rho < DT or rho <= 0 dB."""
        return self._weight(self.snr_db(range_m))

    def weight_bound(self, range_m: ArrayLike) -> np.ndarray:
        """An upper bound of :meth:`weight` over every range at or beyond ``range_m`` (from TL's floor there)."""
        return self._weight(self.snr_at_tl0_db - self.tl.floor_beyond(range_m))
