"""The path between the plane a receiver's reflection was read at and the calibrators' plane.

A VNA reads the receiver (the LNA) at the plane of the standards measured with it. When
those are not the calibrators' standards (EDGES-3: ``*_lna_S/O/L.s1p`` against
``*_S/O/L.s1p``), the receiver seen from the calibrators' plane lies behind a further path,
a two-port with port 1 facing the plane the receiver was read at and port 2 facing the
calibrators' plane (the convention of :mod:`calibration.rf.two_port`). The receiver's
reflection the calibration needs is then eq. (4.7) of the thesis::

    G_rec = S22 + S12 S21 G_read / (1 - S11 G_read)                               (4.7)

and removing a path (the receiver read further out than the calibrators) is eq. (4.6).

Two sources for the path:

* :class:`MeasuredPath`: a two-port Touchstone file (:func:`read_measured_path`), its
  S-parameters interpolated onto the reading's frequencies (no extrapolation).
* :class:`ReceiverCable`: a length of UT-141C-SP semi-rigid line (the model of
  :class:`calibration.rf.coax.PhysicalCoax`, eq. C3 there), with the two empirical
  corrections of EDGES' ``corrcsv`` (MIT EDGES memos 367, 392; edges-cal
  ``path_length_correction_edges3``): the permittivity scaled by ``1 + eps_pct/100``
  and the conductors' conductivity by ``1 + sigma_pct/100``. A positive length adds the
  line by (4.7) (a symmetric line, so its port order does not matter), a negative one
  removes ``|length|`` by (4.6), as ``corrcsv`` does for ``-cablen`` of either sign.

:data:`EDGES3_RECEIVER_CABLE` holds the values EDGES' pipeline used for EDGES-3
(``corrcsv s11.csv -cablen 4.26 -cabdiel -1.24 -cabloss -91.5``: 4.26 inches, -1.24 %,
-91.5 %); on day 2022-319 it turns the corrected receiver reading ``s11.csv`` into
``s11lna.csv`` to 1e-5 (``tests/test_receiver_path.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError
from ..rf.coax import PhysicalCoax
from ..rf.touchstone import read_touchstone_network
from ..rf.two_port import deembed_reflection, embed_reflection, interpolate_s
from .edges_text import UT141C

__all__ = [
    "EDGES3_RECEIVER_CABLE",
    "MeasuredPath",
    "ReceiverCable",
    "ReceiverPath",
    "read_measured_path",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
INCH_M = 0.0254


@dataclass(frozen=True)
class ReceiverCable:
    """A signed length of UT-141C-SP line with EDGES' ``corrcsv`` corrections (module doc).

    ``length_m``: metres, > 0 adds the line (4.7), < 0 removes it (4.6); ``eps_pct``:
    change of the dielectric's permittivity (2.05), percent; ``sigma_pct``: change of the
    conductors' conductivity, percent (``-91.5`` makes them 11.8x more resistive).
    """

    length_m: float
    eps_pct: float = 0.0
    sigma_pct: float = 0.0

    def __post_init__(self) -> None:
        values = (self.length_m, self.eps_pct, self.sigma_pct)
        if not all(np.isfinite(v) for v in values):
            raise InvalidDataError(f"receiver cable: values must be finite, got {values}")
        if self.length_m == 0 or not (self.eps_pct > -100 and self.sigma_pct > -100):
            raise InvalidDataError(
                "receiver cable: needs length_m != 0 (m), eps_pct > -100 and sigma_pct > -100 (%)"
            )

    def line(self) -> PhysicalCoax:
        """The line of ``|length_m|`` (eq. C3 of :mod:`calibration.rf.coax`)."""
        scale = 1 + self.sigma_pct / 100
        return PhysicalCoax(
            a=UT141C["a"],
            b=UT141C["b"],
            eps_r=UT141C["eps_r"] * (1 + self.eps_pct / 100),
            sigma_in=UT141C["sigma_in"] * scale,
            sigma_out=UT141C["sigma_out"] * scale,
            tan_d=UT141C["tan_d"],
            length=abs(self.length_m),
        )

    def apply(self, freq_hz: ArrayLike, gamma_read: ArrayLike) -> ComplexArray:
        """The receiver's reflection at the calibrators' plane, (4.7) or (4.6)."""
        s = self.line().s_parameters(freq_hz)
        if self.length_m > 0:
            return embed_reflection(gamma_read, s)
        return deembed_reflection(gamma_read, s)

    def describe(self) -> str:
        """One line for the importer's report."""
        way = "added" if self.length_m > 0 else "removed"
        return (
            f"UT-141C-SP line of {abs(self.length_m) * 1e3:.1f} mm {way} (permittivity "
            f"{self.eps_pct:+g} %, conductivity {self.sigma_pct:+g} %)"
        )


#: EDGES-3's receiver path as EDGES' pipeline corrects it (``corrcsv`` of the module doc).
EDGES3_RECEIVER_CABLE = ReceiverCable(4.26 * INCH_M, -1.24, -91.5)


@dataclass(frozen=True, eq=False)
class MeasuredPath:
    """A measured two-port: port 1 where the receiver was read, port 2 at the calibrators'."""

    freq_hz: FloatArray
    s: ComplexArray
    origin: str = "two-port"

    def apply(self, freq_hz: ArrayLike, gamma_read: ArrayLike) -> ComplexArray:
        """(4.7) with the file's S-parameters interpolated onto ``freq_hz``."""
        f = np.asarray(freq_hz, dtype=float)
        try:
            s = interpolate_s(self.freq_hz, self.s, f)
        except InvalidDataError as err:
            raise InvalidDataError(f"{self.origin}: {err}") from None
        return embed_reflection(gamma_read, s)

    def describe(self) -> str:
        """One line for the importer's report."""
        return f"two-port {self.origin} (port 1 at the receiver's reading, port 2 at the loads')"


ReceiverPath = ReceiverCable | MeasuredPath


def read_measured_path(path: str | Path) -> MeasuredPath:
    """A two-port Touchstone file as a :class:`MeasuredPath` (a one-port file is refused)."""
    network = read_touchstone_network(path)
    if network.n_ports != 2:
        raise InvalidDataError(f"{path}: a receiver path is a two-port (.s2p) file, not a one-port")
    if network.z0 != 50.0:
        raise InvalidDataError(f"{path}: reference impedance {network.z0:g} ohm, not 50 ohm")
    return MeasuredPath(network.freq_hz, network.s, str(path))
