"""EDGES laboratory calibration runs in text form, with every run-specific choice an input.

The files and their conventions are those of :mod:`calibration.io.edges_text` (Alan Rogers'
pipeline: ``T* = 1000 Q + 300`` spectra, ``BEGIN``/``freq_MHz,re,im`` S11 exports, the
pipeline's modelled S11s). What differs between runs is given, not assumed:

* the calibrators' physical temperatures (:attr:`EdgesImport.temperatures_k`);
* the file names, as patterns with ``{name}`` for the load and shell wildcards
  (``sp{name}.txt``, ``sp{name}_alan.txt``, ``*_{name}.txt``), each matching one file;
* the S11s: the pipeline's models, splines through the VNA exports, or reflections the
  caller supplies (e.g. raw VNA readings corrected by :mod:`calibration.io.vna_import`);
* the loss of the cable between the hot load and its S11 plane: a measured power-gain
  table (:func:`read_gain_table`, judged over the band only), the EDGES cable model
  (:class:`CableLoss`), or none;
* the path between the plane the receiver's reflection was read at and the calibrators'
  plane (:mod:`calibration.io.receiver_path`, eq. 4.7): a two-port file, a cable model, or
  none (the planes coincide).

Every S11 is checked against the band before use: a band beyond an S11's frequencies is
refused naming both, and a reflection ``|Gamma| >= 1`` is refused naming where it starts.

The hot load's temperature at the S11 plane (MIT EDGES memo 132; edges-cal ``alanmode``)::

    T_plane(f) = G(f) T_hot + (1 - G(f)) T_cable                                  (L1)

with ``G`` the cable's available power gain and ``T_cable`` its physical temperature, the
ambient load's by default. :func:`calibration.io.edges_import.load_edges3_run` is this importer
with the settings of day 2022-316.
"""

from __future__ import annotations

import glob
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import CubicSpline

from ..core.errors import FileFormatError, InvalidDataError
from ..model.data import CalibrationData, Integration, SourceData
from .edges_text import (
    INTEGRATION_PER_POSITION_S,
    T_CAL_K,
    T_COLD_K,
    T_HOT_K,
    T_LOAD_K,
    UT141C,
    coax_power_gain,
    empirical_q_variance,
    noise_bandwidth_hz,
    radiometer_q_variance,
    read_modelled_s11,
    read_s11_csv,
    read_spectrum,
)
from .receiver_path import ReceiverPath
from .text_table import read_rows

__all__ = [
    "CableLoss",
    "EdgesImport",
    "EdgesLayout",
    "MeasuredLoss",
    "find_file",
    "import_edges",
    "read_gain_table",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
Reflection = tuple[FloatArray, ComplexArray]  #: ``(freq_hz, gamma)`` on the VNA's own grid
S11Choice = Literal["modelled", "raw"]
QVariance = Literal["empirical", "radiometer"]
_MATCH_HZ = 1.0  # grids printed to 1 Hz (MHz with 6 decimals) count as the same channel


@dataclass(frozen=True)
class EdgesLayout:
    """Where a run's files are: patterns relative to the run's directory.

    ``{name}`` stands for a load (or the receiver) name; ``*``, ``?`` and ``[...]`` are
    shell wildcards. ``modelled_columns`` names the complex column pairs of the modelled
    S11 file after its frequency column.
    """

    loads: tuple[str, ...] = ("amb", "hot", "open", "short")
    receiver: str = "lna"
    spectrum: str = "sp{name}.txt"
    s11_export: str = "s11{name}.csv"
    s11_modelled: str = "s11_modelled.txt"
    modelled_columns: tuple[str, ...] = ("amb", "hot", "open", "short", "lna")


@dataclass(frozen=True)
class MeasuredLoss:
    """A measured power-gain table of the hot load's cable, linear in frequency between rows.

    ``lines`` holds each row's line in the file ``origin``, for messages.
    """

    freq_hz: FloatArray
    gain: FloatArray
    origin: str = "table"
    lines: tuple[int, ...] = ()

    def gain_at(self, freq_hz: FloatArray, gamma_load: ComplexArray) -> FloatArray:
        """``G(f)`` on ``freq_hz`` by linear interpolation; refuses to extrapolate.

        Only the rows the interpolation uses must hold a gain in ``(0, 1]`` (a published
        table, edges-cal's ``hot_load_loss.txt``, runs over the whole spectrum, and its
        model gives gains above 1 far outside the fit band, e.g. at 40 MHz for a 50-190
        MHz fit); a used row that does not is refused as ``file:line: ... at F MHz``.
        """
        del gamma_load  # a measured gain already holds the load's mismatch
        lo, hi = self.freq_hz[0], self.freq_hz[-1]
        if freq_hz[0] < lo - _MATCH_HZ or freq_hz[-1] > hi + _MATCH_HZ:
            raise InvalidDataError(
                f"{self.origin}: the gain table covers {lo / 1e6:.6g}-{hi / 1e6:.6g} MHz, "
                f"not the band {freq_hz[0] / 1e6:.6g}-{freq_hz[-1] / 1e6:.6g} MHz"
            )
        below = np.clip(np.searchsorted(self.freq_hz, freq_hz, "right") - 1, 0, None)
        on_row = np.abs(self.freq_hz[below] - freq_hz) <= _MATCH_HZ
        used = np.union1d(below, np.minimum(below[~on_row] + 1, self.freq_hz.size - 1))
        bad = used[~((self.gain[used] > 0) & (self.gain[used] <= 1))]
        if bad.size:
            i = int(bad[0])
            where = f"{self.origin}:{self.lines[i]}" if self.lines else self.origin
            raise InvalidDataError(
                f"{where}: power gain {self.gain[i]:g} at {self.freq_hz[i] / 1e6:g} MHz is not "
                "in (0, 1]: a passive cable neither amplifies nor blocks"
            )
        return np.asarray(np.interp(freq_hz, self.freq_hz, self.gain), dtype=float)


@dataclass(frozen=True)
class CableLoss:
    """The hot-load cable as a coaxial line (:func:`calibration.io.edges_text.coax_power_gain`).

    ``cable`` holds the line's SI dimensions and materials; the default is the EDGES-3
    hot load's 4-inch UT-141C-SP semi-rigid cable.
    """

    cable: Mapping[str, float] = field(default_factory=lambda: dict(UT141C))

    def gain_at(self, freq_hz: FloatArray, gamma_load: ComplexArray) -> FloatArray:
        """``G(f)`` of the line for a load of S11 ``gamma_load`` at the cable input."""
        missing = sorted(set(UT141C) - set(self.cable))
        if missing:
            raise InvalidDataError(f"the cable model lacks {', '.join(missing)}")
        return coax_power_gain(freq_hz, gamma_load, self.cable)


def read_gain_table(path: str | Path) -> MeasuredLoss:
    """A power-gain table: rows ``freq_MHz gain`` (whitespace or commas, ``#`` comments).

    Frequencies must increase; gains are judged where they are used, over the band
    (:meth:`MeasuredLoss.gain_at`).
    """
    table, lines = read_rows(path, 2)
    freq_hz, gain = table[:, 0] * 1e6, table[:, 1]
    step = np.flatnonzero(np.diff(freq_hz) <= 0)
    if step.size:
        raise FileFormatError(f"{path}:{lines[step[0] + 1]}: frequencies must increase")
    if freq_hz.size < 2:
        raise FileFormatError(f"{path}: a gain table needs at least two rows")
    return MeasuredLoss(freq_hz, gain, str(path), tuple(int(n) for n in lines))


@dataclass(frozen=True)
class EdgesImport:
    """How to read one EDGES run.

    Attributes
    ----------
    temperatures_k
        Physical temperature of every load in ``layout.loads`` (K).
    layout
        File names (:class:`EdgesLayout`).
    band_mhz
        Channels kept, inclusive (to 1 Hz).
    s11
        ``"modelled"``: the pipeline's models, on the spectra's grid; ``"raw"``: cubic
        splines through the VNA exports. Reflections given to :func:`import_edges`
        override both.
    q_variance
        ``"empirical"`` (the spectra's own scatter,
        :func:`calibration.io.edges_text.empirical_q_variance`) or ``"radiometer"`` (the
        noiseless-receiver bound, :func:`calibration.io.edges_text.radiometer_q_variance`).
    hot_loss
        The cable loss of eq. (L1) (:class:`MeasuredLoss`, :class:`CableLoss`) or ``None``.
    receiver_path
        The path from the plane the receiver was read at to the calibrators' plane
        (:mod:`calibration.io.receiver_path`), applied to the receiver's reflection whatever
        its origin, or ``None``.
    lossy_load, cable_load
        The load behind the cable (``hot``) and the load whose temperature the cable
        shares (``amb``).
    integration_per_position_s
        Accumulation time of one Dicke position of one cycle (not in the files).
    """

    temperatures_k: Mapping[str, float]
    layout: EdgesLayout = field(default_factory=EdgesLayout)
    band_mhz: tuple[float, float] = (50.0, 190.0)
    s11: S11Choice = "modelled"
    q_variance: QVariance = "empirical"
    hot_loss: MeasuredLoss | CableLoss | None = field(default_factory=CableLoss)
    lossy_load: str = "hot"
    cable_load: str = "amb"
    integration_per_position_s: float = INTEGRATION_PER_POSITION_S
    receiver_path: ReceiverPath | None = None

    def __post_init__(self) -> None:
        loads = self.layout.loads
        missing = [n for n in loads if n not in self.temperatures_k]
        if missing:
            raise InvalidDataError(f"no temperature given for the loads {', '.join(missing)}")
        unknown = sorted(set(self.temperatures_k) - set(loads))
        if unknown:
            raise InvalidDataError(
                f"temperatures given for {', '.join(unknown)}, which are not loads "
                f"({', '.join(loads)})"
            )
        if self.s11 not in ("modelled", "raw"):
            raise InvalidDataError(f"s11 must be 'modelled' or 'raw', got {self.s11!r}")
        if self.q_variance not in ("empirical", "radiometer"):
            raise InvalidDataError(
                f"q_variance must be 'empirical' or 'radiometer', got {self.q_variance!r}"
            )
        if self.hot_loss is not None:
            for role, name in (("lossy", self.lossy_load), ("cable", self.cable_load)):
                if name not in loads:
                    raise InvalidDataError(f"the {role} load {name!r} is not one of {loads}")
        lo, hi = self.band_mhz
        if not 0 < lo < hi:
            raise InvalidDataError(f"the band needs 0 < LO < HI (MHz), got {lo} {hi}")


def find_file(directory: Path, pattern: str, name: str = "") -> Path:
    """The one file in ``directory`` that ``pattern`` (``{name}`` filled in) matches."""
    wanted = pattern.replace("{name}", glob.escape(name))
    matches = sorted(Path(p) for p in glob.glob(str(directory / wanted)))
    matches = [p for p in matches if p.is_file()]
    if len(matches) != 1:
        found = ", ".join(p.name for p in matches[:5]) if matches else "none"
        raise FileFormatError(
            f"{directory}: {wanted!r} must match one file, matched {len(matches)} ({found})"
        )
    return matches[0]


def import_edges(
    directory: str | Path,
    spec: EdgesImport,
    reflections: Mapping[str, Reflection] | None = None,
) -> CalibrationData:
    """An EDGES run as :class:`CalibrationData`, its calibrators named as ``layout.loads``.

    As :func:`calibration.io.edges_import.load_edges3_run` describes: pseudo-powers ``P_load =
    300``, ``P_ns = 1300``, ``P_src = T*`` (so ``Q = (T* - 300) / 1000``), the noise
    bandwidth as channel width, ``n_spectra x integration_per_position_s`` a position.
    ``reflections`` (``{name: (freq_hz, gamma)}``, every load and the receiver) are
    splined onto the spectra's grid in place of the files' S11s.

    Returns
    -------
    CalibrationData
        ``metadata``: ``n_spectra``, ``headers``, ``hot_load_gain``, ``channel_spacing_hz``,
        ``temperatures_k``, ``files`` and the choices made.
    """
    directory = Path(directory)
    layout = spec.layout
    paths = {name: find_file(directory, layout.spectrum, name) for name in layout.loads}
    spectra = {name: read_spectrum(path) for name, path in paths.items()}
    first = layout.loads[0]
    freq = spectra[first][0]
    mask = (freq >= spec.band_mhz[0] * 1e6 - _MATCH_HZ) & (
        freq <= spec.band_mhz[1] * 1e6 + _MATCH_HZ
    )
    freq = freq[mask]
    if freq.size < 2:
        raise InvalidDataError(f"{paths[first]}: fewer than 2 channels in {spec.band_mhz} MHz")
    names = (*layout.loads, layout.receiver)
    if reflections is not None:
        given = _with_receiver_path(reflections, layout.receiver, spec.receiver_path)
        s11 = {n: _on_grid(freq, given, n, "the corrected reflections", spec) for n in names}
        s11_origin = "given"
    elif spec.s11 == "modelled":
        s11 = _modelled_on_grid(directory, layout, freq, spec.band_mhz, names)
        if spec.receiver_path is not None:
            s11[layout.receiver] = spec.receiver_path.apply(freq, s11[layout.receiver])
        s11_origin = str(find_file(directory, layout.s11_modelled))
    else:
        read = {n: read_s11_csv(find_file(directory, layout.s11_export, n)) for n in names}
        exports = _with_receiver_path(read, layout.receiver, spec.receiver_path)
        s11 = {n: _on_grid(freq, exports, n, layout.s11_export, spec) for n in names}
        s11_origin = layout.s11_export
    for name in names:
        _check_passive(freq, s11[name], name, s11_origin, spec.band_mhz)
    temps: dict[str, FloatArray] = {
        n: np.full(freq.size, 1.0) * spec.temperatures_k[n] for n in layout.loads
    }
    gain = np.ones(freq.size)
    if spec.hot_loss is not None:  # eq. (L1)
        gain = spec.hot_loss.gain_at(freq, s11[spec.lossy_load])
        t_lossy, t_cable = (
            spec.temperatures_k[spec.lossy_load],
            spec.temperatures_k[spec.cable_load],
        )
        temps[spec.lossy_load] = np.full(freq.size, 1.0) * (gain * t_lossy + (1 - gain) * t_cable)
    sources = {}
    for name, (f_load, t_all, n_spec, _) in spectra.items():
        if f_load.shape != mask.shape or not np.array_equal(f_load[mask], freq):
            raise FileFormatError(f"{paths[name]}: not on the frequency grid of {paths[first]}")
        t = t_all[mask]
        if spec.q_variance == "empirical":
            var = empirical_q_variance(t)
        else:
            var = radiometer_q_variance(t, n_spec, spec.integration_per_position_s)
        tau = n_spec * spec.integration_per_position_s
        sources[name] = SourceData(
            name,
            s11[name],
            t,
            np.full(t.size, T_LOAD_K),
            np.full(t.size, T_LOAD_K + T_CAL_K),
            Integration(tau, tau, tau),
            temps[name],
            var,
        )
    meta = {
        "n_spectra": {k: v[2] for k, v in spectra.items()},
        "q_variance": spec.q_variance,
        "headers": {k: v[3] for k, v in spectra.items()},
        "hot_load_gain": gain,
        "channel_spacing_hz": float(np.median(np.diff(freq))),
        "source": str(directory),
        "temperatures_k": dict(spec.temperatures_k),
        "files": {k: str(p) for k, p in paths.items()},
        "s11": s11_origin,
        "hot_load_loss": _loss_name(spec.hot_loss),
    }
    return CalibrationData(freq, s11[layout.receiver], sources, noise_bandwidth_hz(), meta)


def _loss_name(loss: MeasuredLoss | CableLoss | None) -> str:
    if loss is None:
        return "none"
    if isinstance(loss, MeasuredLoss):
        return f"measured gain table {loss.origin}"
    changed = {k: v for k, v in loss.cable.items() if UT141C.get(k) != v}
    return "cable model UT-141C-SP" + (f" with {changed}" if changed else "")


def _modelled_on_grid(
    directory: Path,
    layout: EdgesLayout,
    freq: FloatArray,
    band_mhz: tuple[float, float],
    names: tuple[str, ...],
) -> dict[str, ComplexArray]:
    """The modelled S11 file's columns at the spectra's channels (the same grid, to 1 Hz)."""
    path = find_file(directory, layout.s11_modelled)
    f_mod, columns = read_modelled_s11(path, layout.modelled_columns)
    missing = [n for n in names if n not in columns]
    if missing:
        raise FileFormatError(f"{path}: no column for {', '.join(missing)}")
    _check_range(f_mod, freq, "the modelled S11s", str(path), band_mhz)
    idx = np.minimum(np.searchsorted(f_mod, freq), f_mod.size - 1)
    if not np.allclose(f_mod[idx], freq, rtol=0.0, atol=_MATCH_HZ):
        raise FileFormatError(f"{path}: not on the spectra's frequency grid over {band_mhz} MHz")
    return {n: columns[n][idx] for n in names}


def _with_receiver_path(
    reflections: Mapping[str, Reflection], receiver: str, path: ReceiverPath | None
) -> Mapping[str, Reflection]:
    """``reflections`` with the receiver's moved to the calibrators' plane, on its own grid."""
    if path is None or receiver not in reflections:
        return reflections
    f_rec, g_rec = reflections[receiver]
    return {**reflections, receiver: (f_rec, path.apply(f_rec, g_rec))}


def _on_grid(
    freq: FloatArray,
    reflections: Mapping[str, Reflection],
    name: str,
    origin: str,
    spec: EdgesImport,
) -> ComplexArray:
    """A cubic spline of ``reflections[name]`` at ``freq``; refuses to extrapolate."""
    if name not in reflections:
        raise InvalidDataError(f"{origin}: no reflection for {name!r}")
    f_vna, gamma = reflections[name]
    _check_range(f_vna, freq, f"S11 of {name}", origin, spec.band_mhz)
    return np.asarray(CubicSpline(f_vna, gamma)(freq), dtype=complex)


def _band_text(lo_mhz: float, hi_mhz: float) -> str:
    return f"{lo_mhz:.6g},{hi_mhz:.6g}"


def _check_range(
    f_data: FloatArray, freq: FloatArray, what: str, origin: str, band_mhz: tuple[float, float]
) -> None:
    """Refuse a band that reaches beyond the data's frequencies, naming both.

    Made before any reflection is judged: a spline or model beyond its data is no reading.
    """
    if freq[0] >= f_data[0] - _MATCH_HZ and freq[-1] <= f_data[-1] + _MATCH_HZ:
        return
    lo, hi = f_data[0] / 1e6, f_data[-1] / 1e6
    # to 10 kHz, inside the data
    inside = (max(band_mhz[0], np.ceil(lo * 100) / 100), min(band_mhz[1], np.floor(hi * 100) / 100))
    fix = f"give --band {_band_text(*inside)}" if inside[0] < inside[1] else "no channel is left"
    raise InvalidDataError(
        f"{what} ({origin}) covers {lo:.6g}-{hi:.6g} MHz; --band "
        f"{_band_text(*band_mhz)} reaches beyond: {fix}"
    )


def _check_passive(
    freq: FloatArray, gamma: ComplexArray, name: str, origin: str, band_mhz: tuple[float, float]
) -> None:
    """Refuse ``|Gamma| >= 1``, naming where: a model used beyond its fit, or a bad VNA cal."""
    over = np.flatnonzero(np.abs(gamma) >= 1.0)
    if not over.size:
        return
    worst = int(np.argmax(np.abs(gamma)))
    first = float(freq[over[0]]) / 1e6
    where = f"from {first:.6g} MHz" if over.size > 1 else f"at {first:.6g} MHz"
    fix = "check the VNA calibration"
    if over[0] > 0 and np.all(np.abs(gamma[over[0]:]) >= 1.0):  # a tail: data valid below it
        below = _band_text(band_mhz[0], np.floor(freq[over[0] - 1] / 1e4) / 100)
        fix = f"if its data end there, give --band {below}; else {fix}"
    raise InvalidDataError(
        f"S11 of {name} ({origin}): |Gamma| reaches {abs(gamma[worst]):.4g} at "
        f"{freq[worst] / 1e6:.6g} MHz (>= 1 {where}), impossible for a passive load;\n{fix}"
    )


def load_edges3_run(
    directory: str | Path,
    band_mhz: tuple[float, float] = (50.0, 190.0),
    use_modelled_s11: bool = True,
    q_variance: str = "empirical",
    hot_load_loss: bool = True,
) -> CalibrationData:
    """An EDGES-3 run as :class:`CalibrationData` with sources ``amb, hot, open, short``.

    :func:`calibration.io.edges_import.import_edges` with the settings of day 2022-316 (its
    file names, 306.5 K and 393.22 K, the hot load's UT-141C-SP cable).

    Names follow the files (``amb``: the ambient, i.e. cold, load). Only T* is stored, so
    the Dicke spectra are pseudo-powers ``P_load = 300``, ``P_ns = 1300``, ``P_src = T*``,
    giving ``Q = (T* - 300) / 1000`` exactly. Their scale lacks the receiver's own noise,
    so the engine's radiometer equation on them is a lower bound; ``channel_width_hz`` is
    the noise bandwidth (:func:`noise_bandwidth_hz`), making that bound equal
    :func:`radiometer_q_variance`; ``Integration`` is ``n_spectra x 5.37 s`` a position.

    Parameters
    ----------
    directory, band_mhz
        The run's directory; band kept (``s11_modelled.txt`` covers 50-190 MHz).
    use_modelled_s11
        Use the pipeline's S11 models (the receiver's from the ``lna`` column), else a
        cubic spline through the raw ``s11<load>.csv`` and ``s11lna.csv`` points.
    q_variance
        ``q_variance_override`` of every source: ``"empirical"`` (default,
        :func:`empirical_q_variance`: measured on these very spectra, so it includes the
        receiver's noise and needs neither the integration time nor ``T_rx``, which the
        files lack) or ``"radiometer"`` (:func:`radiometer_q_variance`, the lower bound).
    hot_load_loss
        Give the hot load ``G 393.22 + (1 - G) 306.5`` K with ``G`` of
        :func:`coax_power_gain`, as the published solution did; else 393.22 K.

    Returns
    -------
    CalibrationData
        ``metadata``: ``n_spectra``, headers, ``channel_spacing_hz``, ``hot_load_gain``.
    """
    if q_variance not in ("empirical", "radiometer"):
        raise ValueError(f"q_variance must be 'empirical' or 'radiometer', got {q_variance!r}")
    spec = EdgesImport(
        temperatures_k={"amb": T_COLD_K, "hot": T_HOT_K, "open": T_COLD_K, "short": T_COLD_K},
        band_mhz=band_mhz,
        s11="modelled" if use_modelled_s11 else "raw",
        q_variance="empirical" if q_variance == "empirical" else "radiometer",
        hot_loss=CableLoss(UT141C) if hot_load_loss else None,
    )
    return import_edges(directory, spec)
