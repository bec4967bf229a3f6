"""Effects of a real front-end that the calibration corrections undo (issue 14, item 7).

Each is off by default (every simulation before them is unchanged) and switched on in
:class:`SimEffects`, the ``effects`` of :class:`~reach_receiver.sim.physics.PhysicsConfig`:

* ``mts``: the mechanical transfer switch is a two-port, not a wire. The VNA sees every
  source through the MTS's VNA path ``S_V`` (port 1 at the source), eq. (4.7)::

      G_meas = S22 + S12 S21 G / (1 - S11 G)

  and the LNA sees it through the LNA path ``S_L`` (port 1 at the LNA, port 2 at the
  sources): the reflection ``S11 + S12 S21 G / (1 - S22 G)`` at the noise temperature
  ``g T_src + (1 - g) T_encl`` (eqs. 3.15-3.16, ``g`` the path's available gain with the
  source behind it, the path at the enclosure's temperature). The LNA's own S11 is
  measured at the LNA (the far side of ``S_L``). Both paths are short lossy lines of a
  wrong impedance (:data:`MTS_VNA_PATH`, :data:`MTS_LNA_PATH`), written as Touchstone
  two-ports for the site file. The calibration plane is the sources'.
* ``cable_gradient``: the cable-based sources' terminations (thermocouples at MS3 and
  MS4, TC-08 ports 3 and 4) are ``termination_above_cable_k`` warmer than their cables
  (ports 5 and 6, the enclosure): ``T_src = G T_R + (1 - G) T_cab`` (eq. 4.9) through
  the cable of :func:`calibration.model.reflections.reach_source_reflection`.
* ``hot_cable``: the heated load's 0.3 m cable is at the enclosure's temperature (port 1)
  and loses part of the load's excess the same way.
* ``rfi``: a few narrow, intermittent spikes (an exponentially distributed power, mean
  ``rfi_level`` of the channel's, drawn per spectrum) in every spectrum of the LNA.

What a calibration should recover is then the sky at the sources' plane:
:meth:`~reach_receiver.sim.physics.ReceiverPhysics.true_temperature_k`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from calibration.model.reflections import CABLE_2M, CABLE_10M, HEATED_LOAD_CABLE, Cable
from calibration.model.source_temperatures import available_gain, cable_source_temperature
from calibration.rf.coax import DataSheetCoax
from calibration.rf.touchstone import TouchstoneData, write_touchstone_network
from calibration.rf.two_port import embed_reflection, flip_ports
from reach_receiver.config.corrections import CableSettings, CorrectionSettings

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: The MTS's path from the sources to the VNA (port 1 at the sources).
MTS_VNA_PATH = DataSheetCoax(length_m=0.25, velocity_factor=0.7, loss_db_per_m=0.8, z0_ohm=54.0)
#: The MTS's path from the sources to the LNA (port 1 at the LNA, port 2 at the sources).
MTS_LNA_PATH = DataSheetCoax(length_m=0.12, velocity_factor=0.7, loss_db_per_m=0.8, z0_ohm=47.0)
#: Which cable each cable-based source has, and the TC-08 port on that cable.
SOURCE_CABLES: dict[str, tuple[Cable, int]] = {
    **{name: (CABLE_2M, 5) for name in ("c2r27", "c2r36", "c2r69", "c2r91")},
    **{name: (CABLE_10M, 6) for name in ("c10open", "c10short", "c10r10", "c10r250")},
}
HOT_CABLE_PORT = 1


def cable_model(cable: Cable) -> DataSheetCoax:
    """The matched cable of :mod:`calibration.model.reflections` as a two-port (the same model)."""
    return DataSheetCoax(cable.length_m, cable.velocity_factor, cable.loss_db_per_m_100mhz)


@dataclass(frozen=True)
class SimEffects:
    """Which effects are on (module doc); all off by default."""

    mts: bool = False
    cable_gradient: bool = False
    hot_cable: bool = False
    rfi: bool = False
    termination_above_cable_k: float = 4.0
    rfi_channels_hz: tuple[float, ...] = (62.3e6, 78.0e6, 95.1e6, 118.7e6)
    rfi_level: float = 0.02

    @classmethod
    def all(cls) -> SimEffects:
        """Every effect on."""
        return cls(mts=True, cable_gradient=True, hot_cable=True, rfi=True)

    @property
    def any(self) -> bool:
        """Whether any effect is on."""
        return self.mts or self.cable_gradient or self.hot_cable or self.rfi

    def cables(self) -> dict[str, tuple[Cable, int]]:
        """The sources whose cable has its own temperature: name -> (cable, its TC-08 port)."""
        out = dict(SOURCE_CABLES) if self.cable_gradient else {}
        if self.hot_cable:
            out["hot"] = (HEATED_LOAD_CABLE, HOT_CABLE_PORT)
        return out

    def through_cable(
        self, name: str, gamma: ComplexArray, freq_hz: FloatArray, t_term_k: float, t_cab_k: float
    ) -> float | FloatArray:
        """A source's noise temperature at its cable's input (eq. 4.9), or ``t_term_k``."""
        cable = self.cables().get(name)
        if cable is None:
            return t_term_k
        round_trip = cable[0].round_trip(freq_hz)
        s = cable_model(cable[0]).s_parameters(freq_hz)
        gain = available_gain(s, gamma / round_trip, gamma)
        return cable_source_temperature(gain, t_term_k, t_cab_k)

    def through_mts(
        self, gamma: ComplexArray, t_src: float | FloatArray, freq_hz: FloatArray, t_encl_k: float
    ) -> tuple[ComplexArray, float | FloatArray]:
        """What the LNA sees of a source behind the MTS's LNA path: reflection, temperature."""
        if not self.mts:
            return gamma, t_src
        s = flip_ports(MTS_LNA_PATH.s_parameters(freq_hz))  # port 1 at the source now
        gain = available_gain(s, gamma)
        return embed_reflection(gamma, s), cable_source_temperature(gain, t_src, t_encl_k)

    def at_vna(self, gamma: ComplexArray, freq_hz: FloatArray) -> ComplexArray:
        """A source's reflection as the VNA reads it through the MTS's VNA path."""
        if not self.mts:
            return gamma
        return embed_reflection(gamma, MTS_VNA_PATH.s_parameters(freq_hz))

    def spikes(self, freq_hz: FloatArray, draws: FloatArray) -> FloatArray:
        """Relative excess power per channel for one spectrum (``draws``: exponential(1))."""
        out = np.zeros(freq_hz.shape)
        if self.rfi:
            width = float(freq_hz[1] - freq_hz[0])
            for f, draw in zip(self.rfi_channels_hz, draws, strict=True):
                out[round(f / width)] += self.rfi_level * draw
        return out

    def write_two_ports(self, directory: Path) -> dict[str, str]:
        """The MTS paths as Touchstone files (port 1 at the device), 40-180 MHz at 0.5 MHz."""
        if not self.mts:
            return {}
        freq = np.arange(40e6, 180e6 + 1.0, 0.5e6)
        paths = {}
        for key, path in (("sources", MTS_VNA_PATH), ("lna", MTS_LNA_PATH)):
            file = directory / f"mts_{key}.s2p"
            comment = f"simulated MTS {key} path, port 1 at the device"
            net = TouchstoneData(freq, path.s_parameters(freq), comments=(comment,))
            write_touchstone_network(file, net)
            paths[key] = str(file)
        return paths

    def site_corrections(self, two_ports: dict[str, str]) -> CorrectionSettings:
        """What a site file says of these effects (``two_ports``: :meth:`write_two_ports`)."""
        cables = {
            name: CableSettings(port, None, c.length_m, c.velocity_factor, c.loss_db_per_m_100mhz)
            for name, (c, port) in self.cables().items()
        }
        return CorrectionSettings(
            mts_sources=two_ports.get("sources") if self.mts else None,
            mts_lna=two_ports.get("lna") if self.mts else None,
            cables=cables,
            rfi=self.rfi,
        )
