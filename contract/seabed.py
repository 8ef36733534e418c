"""The seabed presets of ``ocean.seabed`` (docs/ocean.md): fluid half-spaces from Jensen et al. (2011), Table 1.3.

A leaf module (no first-party import), so that the scenario's sections take their choices from this table.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Seabed:
    """A fluid half-space: compressional speed ``cp_mps`` (m/s), density ``rho_gcc`` (g/cm^3), attenuation
    ``ap_db_per_wavelength`` (dB per wavelength)."""

    name: str
    cp_mps: float
    rho_gcc: float
    ap_db_per_wavelength: float


SEABEDS = {
    # Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics (2011), Table 1.3 (cp as its cp/cw times
    # 1500 m/s); "mud" is the table's silt, "rock" its basalt without shear (a fluid approximation)
    "mud": Seabed("mud", 1575.0, 1.7, 1.0),
    "sand": Seabed("sand", 1650.0, 1.9, 0.8),
    "gravel": Seabed("gravel", 1800.0, 2.0, 0.6),
    "rock": Seabed("rock", 5250.0, 2.7, 0.1),
}
