"""Two-port S-parameter algebra: T-parameters, de-embedding and embedding, checks.

Convention (the thesis's, eqs. 3.16, 4.6-4.8): a fixture's **port 1 faces the device**
(the source, a cable's termination, the LNA) and **port 2 faces the reference plane**
(the VNA's calibrated port, the receiver input). Arrays ``s`` have shape ``(..., 2, 2)``
with ``s[..., i, j] = S(i+1)(j+1)``, frequency on the leading axes, as
:class:`~calibration.rf.touchstone.TouchstoneData` holds them. A file recorded the other way
round (port 1 at the VNA: the usual lab habit, and scikit-rf's for ``fixture ** load``) is
:func:`flip_ports` of this; :func:`check_port_order` tells which way a file was recorded.

Scattering transfer parameters, thesis eq. (4.4), with the waves ordered
``[b1, a1] = T [a2, b2]`` (the order for which (4.4) holds; scikit-rf's ``s2t``)::

    T = [[(S12 S21 - S11 S22) / S21,  S11 / S21],
         [-S22 / S21,                 1 / S21 ]]                              (4.4)

so that connecting port 2 of ``A`` to port 1 of ``B`` is the product ``T_A T_B``
(:func:`cascade`). A device of reflection ``G`` on port 1, seen from port 2, reads::

    G_ref = S22 + S12 S21 G / (1 - S11 G)                                (4.7)

(:func:`embed_reflection`: the LNA behind the MTS J2->J4 path), and its inverse::

    G = (G_ref - S22) / (S12 S21 + S11 (G_ref - S22))                    (4.6)

(:func:`deembed_reflection`: a source behind the MTS J1->J2 path). The thesis derives
(4.6) from the wave relation (4.5) of the T-matrix.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError

__all__ = [
    "PortOrderCheck",
    "TwoPortCheck",
    "cascade",
    "check_port_order",
    "check_two_port",
    "compare_port_order",
    "deembed_reflection",
    "deembed_two_port",
    "embed_reflection",
    "flip_ports",
    "interpolate_s",
    "s_to_t",
    "t_to_s",
]

ComplexArray = NDArray[np.complex128]
FloatArray = NDArray[np.float64]

#: Default largest relative difference ``|S21 - S12| / max(|S21|, |S12|)`` of a reciprocal path.
RECIPROCITY_TOL = 0.02
#: Default largest excess of ``S^H S``'s largest eigenvalue over 1 for a passive path.
PASSIVITY_TOL = 0.02


def _s_matrix(s: ArrayLike) -> ComplexArray:
    arr = np.asarray(s, dtype=complex)
    if arr.ndim < 2 or arr.shape[-2:] != (2, 2):
        raise InvalidDataError(f"two-port S-parameters need shape (..., 2, 2), got {arr.shape}")
    return arr


def flip_ports(s: ArrayLike) -> ComplexArray:
    """The same network with its ports renumbered: ``S11 <-> S22`` and ``S12 <-> S21``."""
    return np.asarray(_s_matrix(s)[..., ::-1, ::-1], dtype=complex)


def s_to_t(s: ArrayLike) -> ComplexArray:
    """Scattering transfer parameters of eq. (4.4); needs ``S21 != 0``."""
    m = _s_matrix(s)
    s11, s12, s21, s22 = m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1]
    if np.any(s21 == 0):
        raise InvalidDataError("S21 = 0 at some frequency: no transfer parameters")
    t = np.empty_like(m)
    t[..., 0, 0] = (s12 * s21 - s11 * s22) / s21
    t[..., 0, 1] = s11 / s21
    t[..., 1, 0] = -s22 / s21
    t[..., 1, 1] = 1 / s21
    return t


def t_to_s(t: ArrayLike) -> ComplexArray:
    """Inverse of :func:`s_to_t`: eq. (4.4) solved for S.

    ``S11 = T12/T22``, ``S21 = 1/T22``, ``S22 = -T21/T22``, ``S12 = T11 - T12 T21 / T22``.
    """
    m = _s_matrix(t)
    t11, t12, t21, t22 = m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1]
    s = np.empty_like(m)
    s[..., 0, 0] = t12 / t22
    s[..., 0, 1] = t11 - t12 * t21 / t22
    s[..., 1, 0] = 1 / t22
    s[..., 1, 1] = -t21 / t22
    return s


def cascade(*networks: ArrayLike) -> ComplexArray:
    """Networks connected in a chain, port 2 of each to port 1 of the next (``T_1 T_2 ...``)."""
    if not networks:
        raise InvalidDataError("cascade needs at least one network")
    t = s_to_t(networks[0])
    for net in networks[1:]:
        t = np.asarray(t @ s_to_t(net), dtype=complex)
    return t_to_s(t)


def deembed_two_port(measured: ArrayLike, left: ArrayLike | None = None,
                     right: ArrayLike | None = None) -> ComplexArray:
    """The middle network ``X`` of ``measured = left . X . right`` (chain order of :func:`cascade`).

    ``T_X = T_left^-1 T_measured T_right^-1``, by linear solves rather than inverses.
    """
    t: NDArray[np.complexfloating] = s_to_t(measured)
    if left is not None:
        t = np.linalg.solve(s_to_t(left), t)
    if right is not None:  # X T_r = M  <=>  T_r^T X^T = M^T
        t_r = np.swapaxes(s_to_t(right), -1, -2)
        t = np.swapaxes(np.linalg.solve(t_r, np.swapaxes(t, -1, -2)), -1, -2)
    return t_to_s(t)


def embed_reflection(gamma_device: ArrayLike, s: ArrayLike) -> ComplexArray:
    """Reflection at port 2 of a device ``gamma_device`` on port 1, eq. (4.7).

    ``gamma_device`` broadcasts against ``s[..., 0, 0]`` (one value per frequency).
    """
    m = _s_matrix(s)
    g = np.asarray(gamma_device, dtype=complex)
    s11, s12, s21, s22 = m[..., 0, 0], m[..., 0, 1], m[..., 1, 0], m[..., 1, 1]
    return np.asarray(s22 + s12 * s21 * g / (1 - s11 * g), dtype=complex)


def deembed_reflection(gamma_measured: ArrayLike, s: ArrayLike) -> ComplexArray:
    """Reflection of the device on port 1 from the reading at port 2, eq. (4.6)."""
    m = _s_matrix(s)
    d = np.asarray(gamma_measured, dtype=complex) - m[..., 1, 1]
    return np.asarray(d / (m[..., 0, 1] * m[..., 1, 0] + m[..., 0, 0] * d), dtype=complex)


@dataclass(frozen=True)
class TwoPortCheck:
    """What :func:`check_two_port` found; ``ok`` is False when any ``problems`` were found.

    Attributes
    ----------
    reciprocity
        Per frequency, ``|S21 - S12| / max(|S21|, |S12|)`` (0 for a reciprocal path).
    passivity_excess
        Per frequency, the largest eigenvalue of ``S^H S`` minus 1 (<= 0 when passive).
    problems
        One sentence per failed check, naming the worst frequency.
    """

    reciprocity: FloatArray
    passivity_excess: FloatArray
    problems: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """No problem found."""
        return not self.problems

    def __str__(self) -> str:
        return "two-port ok" if self.ok else "; ".join(self.problems)


def check_two_port(
    s: ArrayLike,
    freq_hz: ArrayLike | None = None,
    name: str = "two-port",
    reciprocity_tol: float = RECIPROCITY_TOL,
    passivity_tol: float = PASSIVITY_TOL,
) -> TwoPortCheck:
    """Check a measured switch path or cable: reciprocal (``S21 = S12``) and passive.

    A passive path of cables and mechanical switches is reciprocal and passive; a file that
    is neither was recorded wrongly (a port not calibrated, the wrong file) or is not such
    a path. Neither check sees a port swap of a reciprocal network: :func:`check_port_order`.
    """
    m = _s_matrix(s)
    s12, s21 = m[..., 0, 1], m[..., 1, 0]
    scale = np.maximum(np.maximum(np.abs(s12), np.abs(s21)), np.finfo(float).tiny)
    recip = np.asarray(np.abs(s21 - s12) / scale, dtype=float)
    gram = np.conj(np.swapaxes(m, -1, -2)) @ m
    excess = np.asarray(np.linalg.eigvalsh(gram)[..., -1] - 1.0, dtype=float)
    freq = None if freq_hz is None else np.asarray(freq_hz, dtype=float)
    problems = []
    for values, tol, what in (
        (recip, reciprocity_tol, "not reciprocal: |S21 - S12| / |S21| reaches"),
        (excess, passivity_tol, "not passive: largest eigenvalue of S^H S exceeds 1 by"),
    ):
        if np.any(values > tol):
            worst = int(np.argmax(values))
            where = f" at {freq.ravel()[worst] / 1e6:.3f} MHz" if freq is not None else ""
            count = int(np.count_nonzero(values > tol))
            problems.append(f"{name} {what} {values.ravel()[worst]:.3g}{where} "
                            f"({count} of {values.size} frequencies above {tol:g})")
    return TwoPortCheck(recip, excess, tuple(problems))


@dataclass(frozen=True)
class PortOrderCheck:
    """What :func:`check_port_order` found.

    Attributes
    ----------
    residual_as_recorded, residual_swapped
        RMS over frequency of ``|G_deembedded - G_expected|`` with the file as recorded and
        with its ports flipped.
    verdict
        ``"as recorded"``, ``"swapped"`` or ``"undecided"`` (the two residuals closer
        than ``margin`` times each other: a nearly symmetric path, or a poor reference).
    """

    residual_as_recorded: float
    residual_swapped: float
    verdict: str

    @property
    def swapped(self) -> bool:
        """The file's ports are the other way round from this module's convention."""
        return self.verdict == "swapped"

    def __str__(self) -> str:
        return (f"port order {self.verdict}: RMS residual {self.residual_as_recorded:.3g} "
                f"as recorded, {self.residual_swapped:.3g} swapped")


def check_port_order(
    s: ArrayLike,
    gamma_measured: ArrayLike,
    gamma_expected: ArrayLike,
    margin: float = 3.0,
) -> PortOrderCheck:
    """Which way round a fixture file was recorded, from one source of known reflection.

    ``gamma_measured`` is the source read through the fixture (at port 2),
    ``gamma_expected`` its reflection known independently (a lab measurement, a model, or
    ``0`` for a matched load). The source is de-embedded with the file as recorded and with
    :func:`flip_ports` of it; the orientation whose result lies nearer the known
    reflection wins when its RMS residual is ``margin`` times smaller than the other's.
    With ``S11 = S22`` both give the same answer and the verdict is ``"undecided"``: a
    symmetric path cannot be recorded the wrong way round.

    The best references differ most between the two orientations: a matched load (the
    wrong orientation returns about ``S11 - S22`` instead of 0) or an open or short at the
    fixture (the wrong orientation is not on the unit circle).
    """
    m = _s_matrix(s)
    expected = np.asarray(gamma_expected, dtype=complex)

    def residual(net: ComplexArray) -> float:
        return _rms(deembed_reflection(gamma_measured, net) - expected)

    return _port_order(residual(m), residual(flip_ports(m)), margin)


def compare_port_order(s: ArrayLike, s_reference: ArrayLike, margin: float = 3.0) -> PortOrderCheck:
    """Which way round a fixture file was recorded, against a trusted recording of the path.

    ``s_reference`` (an earlier lab file of the same path, known to follow this module's
    convention) on the same frequencies; the residuals are RMS ``|S - S_ref|`` over all four
    parameters and frequencies, with the file as recorded and flipped.
    """
    m, ref = _s_matrix(s), _s_matrix(s_reference)
    return _port_order(_rms(m - ref), _rms(flip_ports(m) - ref), margin)


def _rms(diff: ComplexArray) -> float:
    return float(np.sqrt(np.mean(np.abs(diff) ** 2)))


def _port_order(direct: float, flipped: float, margin: float) -> PortOrderCheck:
    if flipped * margin < direct:
        verdict = "swapped"
    elif direct * margin < flipped:
        verdict = "as recorded"
    else:
        verdict = "undecided"
    return PortOrderCheck(direct, flipped, verdict)


def interpolate_s(freq_from_hz: ArrayLike, s: ArrayLike, freq_to_hz: ArrayLike) -> ComplexArray:
    """S-parameters interpolated onto other channels; refuses to extrapolate.

    Linear in real and imaginary parts; any complex array with frequency on axis 0. For a
    fixture file measured on another grid than the run's channels; the grid should be fine
    enough that the phase turns little between points (a 1 m path: 3.6 deg per MHz).
    """
    f0, f1 = np.asarray(freq_from_hz, dtype=float), np.asarray(freq_to_hz, dtype=float)
    values = np.asarray(s, dtype=complex)
    if values.shape[0] != f0.size or f0.ndim != 1 or np.any(np.diff(f0) <= 0):
        raise InvalidDataError("interpolate_s needs strictly increasing frequencies, one per row")
    if f1.size and (f1.min() < f0[0] or f1.max() > f0[-1]):
        raise InvalidDataError(
            f"channels {f1.min() / 1e6:.3f}-{f1.max() / 1e6:.3f} MHz lie outside the file's "
            f"{f0[0] / 1e6:.3f}-{f0[-1] / 1e6:.3f} MHz: no extrapolation"
        )
    flat = values.reshape(f0.size, -1)
    out = np.empty((f1.size, flat.shape[1]), dtype=complex)
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(f1, f0, flat[:, k].real) + 1j * np.interp(f1, f0, flat[:, k].imag)
    return out.reshape((f1.size, *values.shape[1:]))
