"""Reader for EDGES-3 calibration runs in the text format of Alan Rogers' C pipeline.

Files (edges-cal test data ``tests/data/edges3-2022-316-alan``): ``sp<load>.txt`` spectra
``freq_MHz T* weight`` with ``T* = 1000 Q + 300``; after the weight, line 1 holds the number
of averaged Dicke cycles (edges-cal ``alanmode.acqplot7amoon`` returns ``len(q)``, one Q a
three-position cycle, and ``write_spec_txt`` puts it there: ``450`` here); ``s11*.csv``
(``BEGIN``, ``freq_MHz,re,im``); ``s11_modelled.txt``; ``specal.txt`` (the solution).

Noise bandwidth (edges-cal ``acqplot7amoon``, ``tools.gauss_smooth``; ``edges-collab/fastspec``
README, ``pfb.cpp``): fastspec channelises 400 MS/s with a 65536-point polyphase filter
bank (6.1035 kHz) and accumulates each position over ``2**31`` samples (its default,
5.37 s; not in the files, so assumed). Each cycle's Q is smoothed by the window
``exp(-0.69 (2k/8)^2)`` and decimated by 8, so the noise bandwidth is not the 48.83 kHz
spacing but ``(sum w)^2 / sum w^2 x 6.1035 kHz = 73.7 kHz``, with a correlation of 0.25
between neighbouring channels (both checked on the data in ``tests/test_edges3_real.py``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import FileFormatError
from .text_table import read_columns

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

T_LOAD_K, T_CAL_K = 300.0, 1000.0  #: ``T* = T_CAL_K Q + T_LOAD_K``
T_COLD_K, T_HOT_K = 306.5, 393.22  #: physical temperatures of day 2022-316 (README)
LOADS = ("amb", "hot", "open", "short")  #: source names used by :func:`load_edges3_run`
NAMES = (*LOADS, "lna")  #: columns of ``s11_modelled.txt``
RAW_CHANNEL_HZ, SMOOTH = 400e6 / 65536, 8  #: fastspec channel width; acqplot7amoon smoothing
INTEGRATION_PER_POSITION_S = 2.0**31 / 400e6  #: fastspec default accumulation (assumed)
#: UT-141C-SP semi-rigid cable of the hot load (edges-cal ``ee.KNOWN_CABLES``), SI units.
UT141C = {
    "a": 0.0362 * 0.0254 / 2,
    "b": 0.1175 * 0.0254 / 2,
    "eps_r": 2.05,
    "sigma_in": 5.96e7,
    "sigma_out": 0.8 * 5.96e7,
    "tan_d": 2e-4,
    "length": 4 * 0.0254,
}


def read_spectrum(path: str | Path) -> tuple[FloatArray, FloatArray, int, str]:
    """``(freq_hz, t_star, n_spectra, header)`` of an ``sp*.txt`` averaged spectrum."""
    lines = Path(path).read_text(errors="replace").splitlines()
    first = lines[0] if lines else ""
    fields = first.split("//")[0].split()
    if len(fields) < 4 or not fields[3].isdigit():
        raise FileFormatError(f"{path}:1: line 1 lacks the number of averaged spectra")
    data = read_columns(path, 3, comments=("//",))
    return data[:, 0] * 1e6, data[:, 1], int(fields[3]), first.partition("//")[2].strip()


def read_s11_csv(path: str | Path) -> tuple[FloatArray, ComplexArray]:
    """``(freq_hz, gamma)`` of an ``s11*.csv`` file (rows after ``BEGIN``, up to ``END``)."""
    lines = Path(path).read_text(errors="replace").splitlines()
    if not lines or lines[0].strip() != "BEGIN":
        raise FileFormatError(f"{path}:1: no BEGIN line")
    d = read_columns(path, 3, markers=("BEGIN", "END"))
    return d[:, 0] * 1e6, d[:, 1] + 1j * d[:, 2]


def read_modelled_s11(
    path: str | Path, names: tuple[str, ...] = NAMES
) -> tuple[FloatArray, dict[str, ComplexArray]]:
    """``(freq_hz, {name: gamma})`` from ``s11_modelled.txt``: ``freq_MHz`` then re/im pairs."""
    d = read_columns(path, 1 + 2 * len(names))
    return d[:, 0] * 1e6, {n: d[:, 2 * i + 1] + 1j * d[:, 2 * i + 2] for i, n in enumerate(names)}


def read_published_solution(directory: str | Path) -> dict[str, NDArray[Any]]:
    """``specal.txt`` per channel: freq_hz, s11_lna, sca, ofs, t_unc, t_cos, t_sin, weight."""
    d = np.loadtxt(Path(directory) / "specal.txt", usecols=(1, 3, 4, 6, 8, 10, 12, 14, 16))
    keys = ("sca", "ofs", "t_unc", "t_cos", "t_sin", "weight")
    out: dict[str, NDArray[Any]] = {k: d[:, 3 + i] for i, k in enumerate(keys)}
    return out | {"freq_hz": d[:, 0] * 1e6, "s11_lna": d[:, 1] + 1j * d[:, 2]}


def published_calibrated_temperature(
    solution: Mapping[str, NDArray[Any]], t_star: ArrayLike, gamma_src: ArrayLike
) -> FloatArray:
    """Calibrated temperature under the EDGES convention (Monsalve et al. 2017, eq. 7).

    As edges-cal ``noise_waves.calibrated_antenna_temperature``, with ``F`` and
    ``alpha = arg(G F)`` of M17 eqs. 3-4 and ``g = 1 - |G_rec|^2``::

        K1 = |F|^2 (1 - |G|^2) / g,  K2 = |G F|^2 / g,  (K3, K4) = |G F| / g (cos, sin) alpha
        T  = [sca (T* - 300) + 300 - ofs - (T_unc K2 + T_cos K3 + T_sin K4)] / K1

    ``1/K1`` is the thesis's ``X_L``, hence ``T_NS = 1000 sca`` and ``T_L = 300 - ofs``.
    """
    g = np.asarray(gamma_src, dtype=complex)
    gr = np.asarray(solution["s11_lna"], dtype=complex)
    gain = 1.0 - np.abs(gr) ** 2
    f = np.sqrt(gain) / (1.0 - g * gr)
    k1 = np.abs(f) ** 2 * (1.0 - np.abs(g) ** 2) / gain
    sol, gf = solution, g * f  # |G F| cos(alpha) = Re(G F), |G F| sin(alpha) = Im(G F)
    nw = (sol["t_unc"] * np.abs(gf) ** 2 + sol["t_cos"] * gf.real + sol["t_sin"] * gf.imag) / gain
    t = np.asarray(t_star, dtype=float)
    return np.asarray((sol["sca"] * (t - T_LOAD_K) + T_LOAD_K - sol["ofs"] - nw) / k1, dtype=float)


def smoothing_window(smooth: int = SMOOTH) -> FloatArray:
    """The Gaussian window of edges-cal ``tools.gauss_smooth`` over raw channels."""
    y = np.arange(-4 * smooth, 4 * smooth + 1) * 2.0 / smooth
    return np.exp(-0.69 * y**2)


def noise_bandwidth_hz(smooth: int = SMOOTH) -> float:
    """Noise-equivalent bandwidth of one output channel: ``(sum w)^2 / sum w^2`` raw channels."""
    w = smoothing_window(smooth)
    return float(w.sum() ** 2 / np.sum(w**2) * RAW_CHANNEL_HZ)


def neighbour_correlation(lag: int, smooth: int = SMOOTH) -> float:
    """Correlation of the noise of output channels ``lag`` apart (raw channels independent)."""
    w, d = smoothing_window(smooth), lag * smooth
    return float(np.sum(w[: w.size - d] * w[d:]) / np.sum(w**2)) if d < w.size else 0.0


def radiometer_q_variance(
    t_star: ArrayLike,
    n_spectra: int,
    integration_s: float = INTEGRATION_PER_POSITION_S,
    bandwidth_hz: float | None = None,
    t_offset_k: ArrayLike = 0.0,
) -> FloatArray:
    """Radiometer-equation ``var(Q)`` per channel of an averaged spectrum.

    :func:`calibration.model.noise_waves.q_variance` with the positions' powers in T* units,
    ``T* + a``, ``300 + a``, ``1300 + a``, each with ``B tau n`` independent samples:
    ``n_spectra`` cycles of ``integration_s`` (``tau``) in the noise bandwidth
    ``bandwidth_hz`` (default :func:`noise_bandwidth_hz`). ``a = t_offset_k`` is the
    receiver's own noise in T* units, ``(T_L + T_rx) / sca - 300`` for a receiver noise
    temperature ``T_rx``; T* files do not hold it, and the default 0 (a noiseless
    receiver) makes the result a lower bound.
    """
    bandwidth = noise_bandwidth_hz() if bandwidth_hz is None else bandwidth_hz
    bt = bandwidth * integration_s * n_spectra
    a, t = np.asarray(t_offset_k, dtype=float), np.asarray(t_star, dtype=float)
    q = (t - T_LOAD_K) / T_CAL_K
    var = (t + a) ** 2 + (1 - q) ** 2 * (T_LOAD_K + a) ** 2 + q**2 * (T_LOAD_K + T_CAL_K + a) ** 2
    return np.asarray(var / (bt * T_CAL_K**2), dtype=float)


def empirical_q_variance(t_star: ArrayLike, block: int = 128, degree: int = 2) -> FloatArray:
    """``var(Q)`` per channel from the spectrum's own channel-to-channel scatter.

    Second differences of T* remove the smooth spectrum. Per block of ``block`` channels
    their robust variance ``(1.4826 MAD)^2`` is divided by ``6 - 8 rho_1 + 2 rho_2``
    (:func:`neighbour_correlation`: the smoothing correlates neighbours) and a
    degree-``degree`` polynomial in channel index smooths the block values. This measures
    all channel-to-channel scatter, the receiver's own noise included, with no assumed
    integration time.
    """
    t = np.asarray(t_star, dtype=float)
    d2 = np.diff(t, 2)
    factor = 6.0 - 8.0 * neighbour_correlation(1) + 2.0 * neighbour_correlation(2)
    starts = range(0, d2.size - block // 2, block)
    centres = np.array([min(s + block / 2, d2.size - 1) + 1 for s in starts])
    var = np.array(
        [
            (1.4826 * np.median(np.abs(b - np.median(b)))) ** 2 / factor
            for b in (d2[s : s + block] for s in starts)
        ]
    )
    fit = np.polynomial.Polynomial.fit(centres, var, min(degree, var.size - 1))
    smooth = np.clip(fit(np.arange(t.size)), 0.5 * var.min(), None)
    return np.asarray(smooth / T_CAL_K**2, dtype=float)


def receiver_offset_k(
    t_star: ArrayLike,
    q_var: ArrayLike,
    n_spectra: int,
    integration_s: float = INTEGRATION_PER_POSITION_S,
    bandwidth_hz: float | None = None,
) -> FloatArray:
    """The ``t_offset_k`` at which :func:`radiometer_q_variance` equals ``q_var``.

    The larger root of that quadratic in ``a``, per channel (NaN if none). With ``sca``,
    ``ofs`` it gives the receiver noise temperature ``T_rx = sca (300 + a) - (300 - ofs)``.
    """

    def v(a: float) -> FloatArray:  # exactly quadratic in a: fit it from three points
        return radiometer_q_variance(t_star, n_spectra, integration_s, bandwidth_hz, a)

    h, v0 = 100.0, v(0.0)
    c2, c1 = (v(h) + v(-h) - 2 * v0) / (2 * h * h), (v(h) - v(-h)) / (2 * h)
    c0 = v0 - np.asarray(q_var, dtype=float)
    with np.errstate(invalid="ignore"):
        return np.asarray((-c1 + np.sqrt(c1**2 - 4 * c2 * c0)) / (2 * c2), dtype=float)


def coax_power_gain(
    freq_hz: ArrayLike, gamma_load: ArrayLike, cable: Mapping[str, float] = UT141C
) -> FloatArray:
    """Power gain ``G`` of the cable between a load and its S11 reference plane.

    The hot-load loss of the published solution (edges-cal ``alanmode.edges``, ``Lh=-1``:
    ``loss.get_cable_loss_model("UT-141C-SP")``) re-implemented: the line of edges-cal
    ``ee.CoaxialCable`` (Alan Rogers' ``cabl2``: skin-effect resistance and inductance,
    dielectric conductance ``tan_d``), its S-matrix in 50 ohm and the loss of MIT EDGES
    memo 132. ``gamma_load`` is the S11 at the cable input; the load's temperature there
    is ``G T_hot + (1 - G) T_amb``.
    """
    f = np.asarray(freq_hz, dtype=float)
    gam = np.asarray(gamma_load, dtype=complex)
    mu0, eps0 = 1.25663706127e-6, 8.8541878188e-12
    a, b = cable["a"], cable["b"]
    ind = mu0 / (2 * np.pi) * np.log(b / a)
    cap = 2 * np.pi * eps0 * cable["eps_r"] / np.log(b / a)
    skin = [np.sqrt(1 / (np.pi * f * mu0 * cable[s])) for s in ("sigma_in", "sigma_out")]
    disp = (mu0 * skin[0] / (4 * np.pi * a) + mu0 * skin[1] / (4 * np.pi * b)) / ind
    jw = 2j * np.pi * f
    series = 2 * np.pi * f * ind * disp + jw * ind * (1 + disp)
    shunt = 2 * np.pi * f * cap * cable["tan_d"] + jw * cap
    z0, gl = np.sqrt(series / shunt), np.sqrt(series * shunt) * cable["length"]
    denom = (z0**2 + 50.0**2) * np.sinh(gl) + 100.0 * z0 * np.cosh(gl)
    s11, s12 = (z0**2 - 50.0**2) * np.sinh(gl) / denom, 100.0 * z0 / denom
    t = (gam - s11) / (s11 * (gam - s11) + s12**2)
    loss = np.abs(s12**2) * (1 - np.abs(t) ** 2)
    loss /= (1 - np.abs(gam) ** 2) * np.abs(1 - s11 * t) ** 2
    return np.asarray(loss, dtype=float)
