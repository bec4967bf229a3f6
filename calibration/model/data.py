"""Containers for calibration runs: what the receiver measured, checked on construction.

A :class:`SourceData` holds one source's Dicke cycle (the three power spectra, their
integration), its reflection coefficient and, for calibrators, its physical temperature.
A :class:`CalibrationData` holds a run: the frequency axis, the receiver's reflection
coefficient and the calibrators. Invalid input raises :class:`InvalidDataError` naming
the source, so that a bad file is caught before any solving starts.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import InvalidDataError
from .noise_waves import DesignTerms, design_terms, q_from_powers, q_variance

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]


def _channel_array(
    value: ArrayLike, n_channels: int, what: str, source: str | None, dtype: type = float
) -> NDArray[Any]:
    arr: NDArray[Any] = np.asarray(value, dtype=dtype)
    if arr.ndim == 0:
        arr = np.full(n_channels, arr, dtype=dtype)
    if arr.shape != (n_channels,):
        raise InvalidDataError(
            f"{what} has shape {arr.shape}, expected ({n_channels},) to match the frequencies",
            source,
        )
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise InvalidDataError(f"{what} has {bad} non-finite values (NaN or inf)", source)
    return arr


@dataclass(frozen=True)
class Integration:
    """How long each Dicke position was integrated, in seconds (sum over averaged spectra)."""

    source_s: float
    load_s: float
    ns_s: float

    def __post_init__(self) -> None:
        for name in ("source_s", "load_s", "ns_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InvalidDataError(f"integration time {name} must be > 0, got {value}")


@dataclass(frozen=True)
class SourceData:
    """One source seen by the receiver: reflection, Dicke spectra, temperature.

    Parameters
    ----------
    name
        Source name (REACH names: ``hot``, ``cold``, ``r25``, ``c10open``, ``ant``...).
    gamma
        Complex reflection coefficient per channel.
    p_source, p_load, p_ns
        Power spectra at the three Dicke positions (any consistent unit).
    integration
        Integration time of each position; with the channel width it gives the number of
        independent samples ``B tau`` of the radiometer equation.
    temperature_k
        Physical (noise) temperature per channel, or a scalar; ``None`` for a source to be
        calibrated (the antenna).
    q_variance_override
        Variance of Q per channel when it is known better than from the radiometer
        equation (e.g. measured scatter of real averaged spectra).
    temperature_std_k
        Standard uncertainty of the temperature, common to all channels (K): a
        thermometer's error is one offset for the whole spectrum. The radiometric solver
        marginalises it (:func:`calibration.regression.normal_equations.build_normal_equations`).
    gamma_std
        Complex rms random error of ``gamma`` per channel (or a scalar), independent
        between channels (the VNA's trace noise); ``None`` when not known. Carried into
        temperatures by :mod:`calibration.model.reflection_noise`.
    """

    name: str
    gamma: ComplexArray
    p_source: FloatArray
    p_load: FloatArray
    p_ns: FloatArray
    integration: Integration
    temperature_k: FloatArray | None = None
    q_variance_override: FloatArray | None = None
    temperature_std_k: float = 0.0
    gamma_std: FloatArray | float | None = None

    def checked(self, n_channels: int) -> SourceData:
        """Return a copy with arrays coerced to ``n_channels`` and every value checked."""
        name = self.name
        gamma = _channel_array(self.gamma, n_channels, "reflection coefficient", name, complex)
        worst = float(np.max(np.abs(gamma)))
        if worst >= 1.0:
            raise InvalidDataError(
                f"|Gamma| reaches {worst:.6f} >= 1: a passive source reflects less than it "
                "receives (check the VNA calibration)",
                name,
            )
        spectra = [
            _channel_array(p, n_channels, label, name)
            for p, label in (
                (self.p_source, "source spectrum"),
                (self.p_load, "load spectrum"),
                (self.p_ns, "noise-source spectrum"),
            )
        ]
        if np.any(spectra[2] <= spectra[1]):
            bad = int(np.count_nonzero(spectra[2] <= spectra[1]))
            raise InvalidDataError(
                f"P_ns <= P_load in {bad} channels: the noise source was off or the "
                "Dicke positions are swapped",
                name,
            )
        temp = None
        if self.temperature_k is not None:
            temp = _channel_array(self.temperature_k, n_channels, "temperature", name)
            if np.any(temp <= 0):
                raise InvalidDataError("temperature must be > 0 K", name)
        if not (np.isfinite(self.temperature_std_k) and self.temperature_std_k >= 0):
            raise InvalidDataError(
                f"temperature uncertainty must be >= 0 K, got {self.temperature_std_k}", name
            )
        override = None
        if self.q_variance_override is not None:
            override = _channel_array(self.q_variance_override, n_channels, "Q variance", name)
            if np.any(override <= 0):
                raise InvalidDataError("Q variance must be > 0", name)
        gamma_std = None
        if self.gamma_std is not None:
            gamma_std = _channel_array(self.gamma_std, n_channels, "reflection error", name)
            if np.any(gamma_std < 0):
                raise InvalidDataError("reflection error must be >= 0", name)
        return replace(
            self,
            gamma=gamma,
            gamma_std=gamma_std,
            p_source=spectra[0],
            p_load=spectra[1],
            p_ns=spectra[2],
            temperature_k=temp,
            q_variance_override=override,
        )

    @property
    def q(self) -> FloatArray:
        """The measured ``Q`` of eq. 3.9."""
        return q_from_powers(self.p_source, self.p_load, self.p_ns)

    def q_variance(self, channel_width_hz: float) -> FloatArray:
        """Variance of Q: the override if given, else the radiometer equation."""
        if self.q_variance_override is not None:
            return self.q_variance_override
        i = self.integration
        return q_variance(
            self.p_source,
            self.p_load,
            self.p_ns,
            channel_width_hz * i.source_s,
            channel_width_hz * i.load_s,
            channel_width_hz * i.ns_s,
        )

    def select(self, mask: NDArray[np.bool_]) -> SourceData:
        """The same source restricted to the channels where ``mask`` is true."""

        def pick(a: NDArray[Any] | None) -> Any:
            return None if a is None else a[mask]

        return replace(
            self,
            gamma=self.gamma[mask],
            p_source=self.p_source[mask],
            p_load=self.p_load[mask],
            p_ns=self.p_ns[mask],
            temperature_k=pick(self.temperature_k),
            q_variance_override=pick(self.q_variance_override),
            gamma_std=None if self.gamma_std is None else np.broadcast_to(
                self.gamma_std, self.gamma.shape
            )[mask],
        )


@dataclass(frozen=True)
class CalibrationData:
    """A calibration run: frequencies, receiver reflection and the calibrators.

    Every calibrator needs a temperature. Arrays are checked and coerced on construction.
    ``gamma_rec_std`` is the complex rms random error of ``gamma_rec`` per channel (or a
    scalar), as :attr:`SourceData.gamma_std` is of a source's; ``None`` when not known.
    ``reflection_correlation_channels`` is how many neighbouring channels share one
    reflection error (1: independent per channel; an S11 sweep of step ``d`` interpolated
    onto channels of width ``w`` shares each point's error over ``d / w`` channels), which
    the posterior needs (:mod:`calibration.solve.correlated_reflections`).
    """

    freq_hz: FloatArray
    gamma_rec: ComplexArray
    sources: Mapping[str, SourceData]
    channel_width_hz: float
    metadata: Mapping[str, Any] = field(default_factory=dict)
    gamma_rec_std: FloatArray | float | None = None
    reflection_correlation_channels: float = 1.0

    def __post_init__(self) -> None:
        freq = np.asarray(self.freq_hz, dtype=float)
        if freq.ndim != 1 or freq.size < 2:
            raise InvalidDataError("frequencies must be a 1-D array of at least 2 channels")
        if not np.all(np.isfinite(freq)) or np.any(np.diff(freq) <= 0):
            raise InvalidDataError("frequencies must be finite and strictly increasing")
        n = freq.size
        gamma_rec = _channel_array(self.gamma_rec, n, "receiver reflection", "receiver", complex)
        if np.max(np.abs(gamma_rec)) >= 1.0:
            raise InvalidDataError("|Gamma_rec| >= 1", "receiver")
        if self.gamma_rec_std is not None:
            rec_std = _channel_array(self.gamma_rec_std, n, "reflection error", "receiver")
            if np.any(rec_std < 0):
                raise InvalidDataError("reflection error must be >= 0", "receiver")
            object.__setattr__(self, "gamma_rec_std", rec_std)
        if not (np.isfinite(self.reflection_correlation_channels)
                and self.reflection_correlation_channels >= 1):
            raise InvalidDataError(
                "reflection_correlation_channels must be >= 1 (channels sharing one "
                f"reflection error), got {self.reflection_correlation_channels}"
            )
        if not (np.isfinite(self.channel_width_hz) and self.channel_width_hz > 0):
            raise InvalidDataError(f"channel width must be > 0, got {self.channel_width_hz}")
        if not self.sources:
            raise InvalidDataError("a calibration run needs at least one calibrator")
        checked: dict[str, SourceData] = {}
        for key, src in self.sources.items():
            if key != src.name:
                raise InvalidDataError(f"stored under the key {key!r}", src.name)
            if src.temperature_k is None:
                raise InvalidDataError("a calibrator needs its physical temperature", key)
            checked[key] = src.checked(n)
        object.__setattr__(self, "freq_hz", freq)
        object.__setattr__(self, "gamma_rec", gamma_rec)
        object.__setattr__(self, "sources", checked)
        object.__setattr__(self, "metadata", dict(self.metadata))

    @property
    def names(self) -> list[str]:
        """Calibrator names in their stored order."""
        return list(self.sources)

    @property
    def n_channels(self) -> int:
        """Number of frequency channels."""
        return int(self.freq_hz.size)

    def terms(self) -> DesignTerms:
        """Design terms of every calibrator, stacked ``(n_sources, n_channels)``."""
        gammas = np.stack([s.gamma for s in self.sources.values()])
        return design_terms(gammas, self.gamma_rec[None, :])

    def temperatures(self) -> FloatArray:
        """Every calibrator's temperature, ``(n_sources, n_channels)`` (K)."""
        return np.stack([s.temperature_k for s in self.sources.values()])  # type: ignore[misc]

    def stacked(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(T, Q, var Q)`` of every calibrator, each ``(n_sources, n_channels)``."""
        temps = self.temperatures()
        q = np.stack([s.q for s in self.sources.values()])
        var = np.stack([s.q_variance(self.channel_width_hz) for s in self.sources.values()])
        return temps, q, var

    def reflection_errors(self) -> FloatArray | None:
        """``(n_sources, n_channels)`` rms reflection errors, ``None`` if none is known."""
        stds = [s.gamma_std for s in self.sources.values()]
        if all(v is None for v in stds):
            return None
        return np.stack([np.zeros(self.n_channels) if v is None else v for v in stds])

    def temperature_variances(self) -> FloatArray:
        """Variance of each calibrator's temperature offset (K^2), in source order."""
        return np.array([s.temperature_std_k**2 for s in self.sources.values()], dtype=float)

    def subset(self, names: Iterable[str]) -> CalibrationData:
        """The same run with only the named calibrators (in the given order)."""
        names = list(names)
        missing = [n for n in names if n not in self.sources]
        if missing:
            raise InvalidDataError(f"no such calibrators: {missing}; have {self.names}")
        return replace(self, sources={n: self.sources[n] for n in names})

    def band(self, f_lo_hz: float, f_hi_hz: float) -> CalibrationData:
        """The same run restricted to ``f_lo_hz <= nu <= f_hi_hz``."""
        mask = (self.freq_hz >= f_lo_hz) & (self.freq_hz <= f_hi_hz)
        return self.select(mask, f"the band {f_lo_hz}-{f_hi_hz} Hz")

    def select(self, mask: NDArray[np.bool_], what: str = "the selection") -> CalibrationData:
        """The same run on the channels where ``mask`` is true (at least two)."""
        if np.count_nonzero(mask) < 2:
            raise InvalidDataError(f"{what} leaves fewer than 2 channels")
        return replace(
            self,
            freq_hz=self.freq_hz[mask],
            gamma_rec=self.gamma_rec[mask],
            sources={n: s.select(mask) for n, s in self.sources.items()},
            gamma_rec_std=None if self.gamma_rec_std is None else (
                np.asarray(self.gamma_rec_std)[mask]
            ),
        )


def check_source(source: SourceData, n_channels: int) -> SourceData:
    """Check a source to be calibrated (its temperature may be unknown)."""
    return source.checked(n_channels)
