"""HDF5 files of the calibration engine: the run files (REACH layout) and the shared helpers.

Every file carries root attributes ``format`` (its kind), ``format_version`` (``"1.0"``;
another major version is refused; a run file without it is read as REACH-native) and
``software``. Writes are atomic: a temporary file beside the target is written, flushed,
synced and moved over the target (:func:`os.replace`). Errors name the file and what is
wrong (:class:`FileFormatError`) or the file and the source (:class:`InvalidDataError`).

Run files (``format = "reach-calibration-run"``, or ``"reach-receiver-run"`` for the run files
of :mod:`reach_receiver.store`, which add their own groups beside this layout) use the
layout of REACH's own tools::

    /observation_data/frequencies              (n,) float, Hz
    /observation_data/lna_s11                  (n,) complex: receiver reflection
    /observation_data/lna_s11_std              (n,) optional rms random error of lna_s11
    /observation_data/{src}_spectra            P_source, (n,) or (n_spectra, n)
    /observation_data/{src}_load_spectra       P_load,   (n,) or (n_spectra, n)
    /observation_data/{src}_ns_spectra         P_NS,     (n,) or (n_spectra, n)
    /observation_data/{src}_s11                (n,) complex: source reflection
    /observation_data/{src}_q_variance         (n,) optional override of var(Q)
    /observation_data/{src}_s11_std            (n,) optional rms random error of {src}_s11
    /observation_metadata/temperatures/{src}   (n,) or scalar, K: calibrators only;
                                               attribute std_k: its uncertainty (K)
    /simulation_truth/{orders, coefficients, gain_coefficients, offset_coefficients_k}

``{src}_timestamps`` are allowed and ignored. Attributes: ``units`` on every dataset; on
``observation_metadata``: ``channel_width_hz``, ``calibrators`` and ``sources`` (names in
order; without them every source with a temperature is a calibrator, sorted by name); on
``{src}_spectra``: ``integration_s_source``, ``integration_s_load``, ``integration_s_ns``
(if absent, the same attributes on ``observation_metadata`` hold for every source); root
``metadata``: the run's metadata as JSON; on ``simulation_truth``: ``basis_kind``,
``basis_f_lo_hz``, ``basis_f_hi_hz`` (only in simulated runs: the receiver simulated).

Optional root attributes of a run file (strings; read with :func:`run_noise_source_model`
and :func:`run_power_spectra`):

* ``noise_source_model``: the noise source the run's ``{src}_ns_spectra`` were taken with.
  ``"NC346A"`` (the Noisecom diode of REACH's receiver, thesis table 2.1) is written by
  REACH's own run layer and by simulations of that diode; only where it is ``"NC346A"``
  is the fitted ``T_NS`` held to that diode's ENR table. Absent (imports of other
  instruments' data, e.g. EDGES) means unknown: no ENR check.
* ``power_spectra``: ``"placeholder"`` when the ``*_spectra`` are not measured powers but
  stand-ins that only carry ``Q`` (``reach-cal import edges`` writes ``P_load = 300``,
  ``P_NS = 1300``, ``P_src = T*``); ``"measured"`` or absent otherwise. Such powers must
  not be shown as measurements.

**Integration-time convention.** ``integration_s_*`` is the integration time of *one row*
of the matching spectra dataset; a 1-D dataset is one row. A 2-D dataset of ``n_spectra``
rows (REACH's repeated spectra) is averaged over its first axis on reading, with integration
time ``n_spectra * integration_s_*``; with ``row_integration_s_*`` (each row's time, rows of
unequal length) the average is weighted by it and the time is its sum. We write 1-D
(averaged) spectra with their total time.

Solution files and calibrated spectra are written and read by :mod:`calibration.io.solution_file`,
which shares this module's atomic writes and checked readers.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import FileFormatError, InvalidDataError
from ..model.basis import PolynomialBasis
from ..model.data import CalibrationData, Integration, SourceData, check_source
from ..model.noise_waves import N_PARAMETERS, PARAMETERS
from ..model.polynomial_model import Orders, PolynomialParameters, as_orders
from ..model.simulate import ReceiverTruth
from ..solve.solution import MAX_FILE_ORDER

PathLike = str | os.PathLike[str]
FORMAT_VERSION = "1.0"
RUN_FORMAT = "reach-calibration-run"
#: The receiver's run files (``reach_receiver.store``): this run layout plus their own groups.
RECEIVER_RUN_FORMAT = "reach-receiver-run"
RUN_FORMATS = (RUN_FORMAT, RECEIVER_RUN_FORMAT)
SOLUTION_FORMAT = "reach-calibration-solution"
#: ``solution_kind`` of a solution file: polynomial (the default when absent) or per channel.
POLYNOMIAL_KIND, PER_CHANNEL_KIND = "polynomial", "per-channel"
CALIBRATED_FORMAT = "reach-calibrated-spectrum"
#: What a calibrated spectrum's ``lower_NN``/``upper_NN`` datasets hold.
INTERVAL_DESCRIPTION = "an end of the central NN % credible interval of the full predictive"
POWER_UNITS = "arbitrary (spectrometer power)"
GAMMA_UNITS = "1 (complex reflection coefficient)"
_MAJOR = FORMAT_VERSION.split(".")[0]
_RESERVED_ATTRS = {"format", "format_version", "software", "metadata"}
_POSTERIOR_FLOATS = ("dof", "log_evidence", "noise_variance", "chi2")
_POSITIONS = (("source", "spectra"), ("load", "load_spectra"), ("ns", "ns_spectra"))
_TRUTH_TUPLES = ("gain_coefficients", "offset_coefficients_k")


def attr_text(value: Any) -> str:
    """An HDF5 attribute or scalar dataset as text (bytes decoded, a 0-d array unwrapped)."""
    if isinstance(value, np.ndarray) and value.shape == ():
        value = value[()]
    return value.decode() if isinstance(value, bytes) else str(value)


def software_version() -> str:
    """Name and version of the writing software, as stored in every file."""
    try:
        return f"reach-receiver {importlib_metadata.version('reach-receiver')}"
    except importlib_metadata.PackageNotFoundError:
        return "reach-receiver (not installed)"


def _json(value: Mapping[str, Any]) -> str:
    """JSON of metadata; numpy values become lists/scalars, anything else its ``str``."""
    return json.dumps(dict(value), default=lambda v: getattr(v, "tolist", lambda: str(v))())


@contextlib.contextmanager
def _atomic_h5(path: PathLike, file_format: str) -> Iterator[Any]:
    """Yield an open HDF5 file that replaces ``path`` only once completely written."""
    target = Path(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    os.close(fd)
    try:
        os.chmod(tmp, target.stat().st_mode & 0o777 if target.exists() else 0o644)
        with h5py.File(tmp, "w") as f:
            f.attrs.update(format=file_format, format_version=FORMAT_VERSION)
            f.attrs["software"] = software_version()
            yield f
            f.flush()
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _dataset(group: Any, name: str, value: ArrayLike, units: str) -> Any:
    ds = group.create_dataset(name, data=np.asarray(value))
    ds.attrs["units"] = units
    return ds


@contextlib.contextmanager
def _open(path: PathLike, file_format: str | tuple[str, ...]) -> Iterator[Any]:
    """Open ``path`` for reading and check its ``format`` (one of ``file_format``) and version."""
    formats = (file_format,) if isinstance(file_format, str) else file_format
    p = Path(path)
    if not p.is_file():
        if p.exists():
            raise FileFormatError(f"{p}: not a regular file")
        raise FileNotFoundError(2, "no such file", str(p))
    try:
        f = h5py.File(p, "r")
    except OSError as err:
        raise FileFormatError(f"{p}: not a readable HDF5 file ({err})") from err
    with f:
        found = f.attrs.get("format")
        if found is not None and attr_text(found) not in formats:
            expected = " or ".join(repr(k) for k in formats)
            raise FileFormatError(f"{p}: is a {attr_text(found)!r} file, expected {expected}")
        version = f.attrs.get("format_version")
        if version is None and RUN_FORMAT not in formats:
            raise FileFormatError(f"{p}: no 'format_version' attribute at the root")
        if version is not None and attr_text(version).split(".")[0] != _MAJOR:
            raise FileFormatError(
                f"{p}: format_version {attr_text(version)!r} has an unknown major version; "
                f"this reader understands {_MAJOR}.x"
            )
        yield f


def _group(parent: Any, name: str, path: PathLike) -> Any:
    obj = parent.get(name)
    if not isinstance(obj, h5py.Group):
        raise FileFormatError(f"{path}: missing group '{parent.name.rstrip('/')}/{name}'")
    return obj


def _array(parent: Any, name: str, path: PathLike, kinds: str = "iuf") -> NDArray[Any]:
    obj = parent.get(name)
    where = f"{parent.name.rstrip('/')}/{name}"
    if not isinstance(obj, h5py.Dataset):
        raise FileFormatError(f"{path}: missing dataset '{where}'")
    value = np.asarray(obj[()])
    if value.dtype.kind not in kinds:
        raise FileFormatError(f"{path}: dataset '{where}' has the wrong dtype {value.dtype}")
    return value


def _attr(obj: Any, name: str, path: PathLike) -> Any:
    if name not in obj.attrs:
        raise FileFormatError(f"{path}: missing attribute '{name}' on '{obj.name}'")
    return obj.attrs[name]


def _names(obj: Any, key: str) -> list[str] | None:
    return [attr_text(n) for n in np.atleast_1d(obj.attrs[key])] if key in obj.attrs else None


def _metadata(f: Any, path: PathLike) -> dict[str, Any]:
    with contextlib.suppress(json.JSONDecodeError):
        value = json.loads(attr_text(f.attrs.get("metadata", "{}")))
        if isinstance(value, dict):
            return value
    raise FileFormatError(f"{path}: root attribute 'metadata' is not a JSON object")


def _in_file(err: InvalidDataError, path: PathLike) -> InvalidDataError:
    out = InvalidDataError(f"{path}: {err}")
    out.source = err.source
    return out


def _number(obj: Any, name: str, path: PathLike, default: float | None = None) -> float:
    """A numeric attribute (a non-number is a format error, not a traceback).

    ``default`` is its value when absent; without one, an absent attribute is an error.
    """
    if default is not None and name not in obj.attrs:
        return default
    value = _attr(obj, name, path)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise FileFormatError(
            f"{path}: attribute '{name}' on '{obj.name}' is not a number: {value!r}"
        ) from None



def write_run(
    path: PathLike,
    data: CalibrationData,
    extra_sources: Mapping[str, SourceData] | None = None,
    attrs: Mapping[str, Any] | None = None,
    truth: ReceiverTruth | None = None,
) -> None:
    """Write a calibration run in the REACH layout (module docstring), atomically.

    Parameters
    ----------
    extra_sources
        Sources that are not calibrators (e.g. the antenna ``ant``), by name.
    attrs
        Extra root attributes (not ``format``, ``format_version``, ``software``, ``metadata``).
    truth
        The simulated receiver, stored in ``simulation_truth``.
    """
    extra = dict(extra_sources or {})
    bad = sorted(set(extra) & set(data.sources)) + [k for k, s in extra.items() if k != s.name]
    if bad:
        raise InvalidDataError(f"extra sources {bad} are calibrators too or not keyed by name")
    if _RESERVED_ATTRS & set(attrs or {}):
        raise ValueError(f"root attributes {sorted(_RESERVED_ATTRS)} are written by write_run")
    sources = {**data.sources, **{k: check_source(s, data.n_channels) for k, s in extra.items()}}
    with _atomic_h5(path, RUN_FORMAT) as f:
        f.attrs.update({**dict(attrs or {}), "metadata": _json(data.metadata)})
        obs = f.create_group("observation_data")
        _dataset(obs, "frequencies", data.freq_hz, "Hz")
        _dataset(obs, "lna_s11", data.gamma_rec, GAMMA_UNITS)
        if data.gamma_rec_std is not None:
            rec_std = np.broadcast_to(data.gamma_rec_std, data.freq_hz.shape)
            _dataset(obs, "lna_s11_std", rec_std, "1")
        meta = f.create_group("observation_metadata")
        meta.attrs.update(
            channel_width_hz=float(data.channel_width_hz),
            calibrators=list(data.names),
            sources=list(sources),
            reflection_correlation_channels=float(data.reflection_correlation_channels),
        )
        temps = meta.create_group("temperatures")
        for name, src in sources.items():
            spectra = _dataset(obs, f"{name}_spectra", src.p_source, POWER_UNITS)
            for p, _ in _POSITIONS:
                spectra.attrs[f"integration_s_{p}"] = float(getattr(src.integration, f"{p}_s"))
            _dataset(obs, f"{name}_load_spectra", src.p_load, POWER_UNITS)
            _dataset(obs, f"{name}_ns_spectra", src.p_ns, POWER_UNITS)
            _dataset(obs, f"{name}_s11", src.gamma, GAMMA_UNITS)
            if src.q_variance_override is not None:
                _dataset(obs, f"{name}_q_variance", src.q_variance_override, "1")
            if src.gamma_std is not None:
                std = np.broadcast_to(src.gamma_std, src.gamma.shape)
                _dataset(obs, f"{name}_s11_std", std, "1")
            if src.temperature_k is not None:
                t = _dataset(temps, name, src.temperature_k, "K")
                t.attrs["std_k"] = float(src.temperature_std_k)
        if truth is not None:
            g = f.create_group("simulation_truth")
            params = truth.parameters
            g.attrs.update(
                basis_kind=params.basis.kind,
                basis_f_lo_hz=params.basis.f_lo_hz,
                basis_f_hi_hz=params.basis.f_hi_hz,
                parameters=list(PARAMETERS),
            )
            _dataset(g, "orders", np.asarray(params.orders, dtype=np.int64), "terms")
            _dataset(g, "coefficients", params.coefficients, "K")
            _dataset(g, _TRUTH_TUPLES[0], np.asarray(truth.gain_coefficients), "power per K")
            _dataset(g, _TRUTH_TUPLES[1], np.asarray(truth.offset_coefficients_k), "K")


def _read_source(obs: Any, meta: Any, temps: Any, name: str, path: PathLike) -> SourceData:
    """One source; 2-D spectra averaged over their first axis, times scaled to match."""
    powers, seconds = [], []
    for position, suffix in _POSITIONS:
        arr = _array(obs, f"{name}_{suffix}", path).astype(float)
        key, first = f"integration_s_{position}", obs[f"{name}_spectra"]
        holder = meta if key in meta.attrs and key not in first.attrs else first
        per_row = _number(holder, key, path)
        if arr.ndim not in (1, 2) or arr.shape[0] == 0:
            raise FileFormatError(f"{path}: {name}_{suffix} has shape {arr.shape}: not 1-D/2-D")
        rows = np.asarray(first.attrs.get(f"row_integration_s_{position}", []), dtype=float)
        if arr.ndim == 2 and rows.shape == (arr.shape[0],) and np.all(rows > 0):
            # Rows of unequal integration: P = sum t_k P_k / sum t_k, one spectrum of sum t_k
            powers.append(rows @ arr / rows.sum())
            seconds.append(float(rows.sum()))
            continue
        powers.append(arr.mean(axis=0) if arr.ndim == 2 else arr)
        seconds.append(per_row * (arr.shape[0] if arr.ndim == 2 else 1))
    gamma = _array(obs, f"{name}_s11", path, "iufc").astype(complex)
    temperature = _array(temps, name, path).astype(float) if name in temps else None
    std_k = _number(temps[name], "std_k", path, 0.0) if name in temps else 0.0
    q_var = f"{name}_q_variance"
    override = _array(obs, q_var, path).astype(float) if q_var in obs else None
    s11_std = f"{name}_s11_std"
    gamma_std = _array(obs, s11_std, path).astype(float) if s11_std in obs else None
    try:
        integration = Integration(*seconds)
    except InvalidDataError as err:
        raise InvalidDataError(str(err), name) from err
    p_src, p_load, p_ns = powers
    return SourceData(
        name, gamma, p_src, p_load, p_ns, integration, temperature, override, std_k, gamma_std
    )


#: ``noise_source_model`` of a run whose noise source is REACH's NC346A diode.
NC346A = "NC346A"
#: ``power_spectra`` of a run whose spectra are stand-ins carrying only Q.
PLACEHOLDER_POWERS, MEASURED_POWERS = "placeholder", "measured"


def _root_string(path: PathLike, name: str) -> str | None:
    with _open(path, RUN_FORMATS) as f:
        value = f.attrs.get(name)
    return None if value is None else attr_text(value)


def run_noise_source_model(path: PathLike) -> str | None:
    """The run's ``noise_source_model`` root attribute (module docstring), ``None`` if absent."""
    return _root_string(path, "noise_source_model")


def run_power_spectra(path: PathLike) -> str:
    """The run's ``power_spectra``: ``"placeholder"`` or ``"measured"`` (the default)."""
    value = _root_string(path, "power_spectra")
    if value not in (None, PLACEHOLDER_POWERS, MEASURED_POWERS):
        raise FileFormatError(
            f"{path}: root attribute 'power_spectra' is {value!r}, not "
            f"{PLACEHOLDER_POWERS!r} or {MEASURED_POWERS!r}"
        )
    return value or MEASURED_POWERS


def read_run(path: PathLike) -> tuple[CalibrationData, dict[str, SourceData]]:
    """Read a run file: the calibrators, and the other sources (e.g. ``ant``) by name.

    2-D spectra are averaged over their first axis (module docstring).
    """
    with _open(path, RUN_FORMATS) as f:
        return read_run_group(f, path)


@dataclass(frozen=True)
class RunLayout:
    """A run layout as read: the axis, the receiver, every source and which calibrate.

    ``sources`` holds every source (calibrators and others, e.g. ``ant``) by name.
    """

    freq_hz: NDArray[np.float64]
    gamma_rec: NDArray[np.complex128]
    channel_width_hz: float
    sources: Mapping[str, SourceData]
    calibrators: tuple[str, ...]
    metadata: Mapping[str, Any]
    path: str
    gamma_rec_std: NDArray[np.float64] | None = None
    reflection_correlation_channels: float = 1.0

    def split(self) -> tuple[CalibrationData, dict[str, SourceData]]:
        """The calibrators as a checked run, and the other sources (checked) by name."""
        try:
            cals = {n: self.sources[n] for n in self.calibrators}
            data = CalibrationData(
                self.freq_hz, self.gamma_rec, cals, self.channel_width_hz, self.metadata,
                self.gamma_rec_std, self.reflection_correlation_channels,
            )
            return data, self.others()
        except InvalidDataError as err:
            raise _in_file(err, self.path) from err

    def others(self) -> dict[str, SourceData]:
        """The sources that are not calibrators, checked against the axis."""
        n = self.freq_hz.size
        try:
            return {
                k: check_source(s, n) for k, s in self.sources.items() if k not in self.calibrators
            }
        except InvalidDataError as err:
            raise _in_file(err, self.path) from err


def read_run_group(f: Any, path: PathLike) -> tuple[CalibrationData, dict[str, SourceData]]:
    """Read the run layout of an open HDF5 file (``path`` names it in errors).

    What :func:`read_run` does after opening and checking the file; the receiver's run
    store uses it on a layout built in memory, so that the calibration made during a
    run and ``reach-cal solve`` on the run file read their data the same way.
    """
    return read_run_layout(f, path).split()


def read_run_layout(f: Any, path: PathLike) -> RunLayout:
    """Every source of an open run layout, before it is split into calibrators and others."""
    obs = _group(f, "observation_data", path)
    meta = _group(f, "observation_metadata", path)
    temps = _group(meta, "temperatures", path)
    freq = _array(obs, "frequencies", path).astype(float)
    gamma_rec = _array(obs, "lna_s11", path, "iufc").astype(complex)
    width = _number(meta, "channel_width_hz", path)
    discovered = sorted(k[:-4] for k in obs if k.endswith("_s11") and k != "lna_s11")
    names = _names(meta, "sources") or discovered
    calibrators = _names(meta, "calibrators") or [n for n in names if n in temps]
    missing = [n for n in calibrators if n not in names]
    if missing:
        raise FileFormatError(f"{path}: calibrators {missing} have no data")
    run_metadata = _metadata(f, path)
    try:
        sources = {n: _read_source(obs, meta, temps, n, path) for n in names}
    except InvalidDataError as err:
        raise _in_file(err, path) from err
    rec_std = _array(obs, "lna_s11_std", path).astype(float) if "lna_s11_std" in obs else None
    # channels sharing one reflection error (older files: independent, 1)
    shared = _number(meta, "reflection_correlation_channels", path, 1.0)
    return RunLayout(
        freq, gamma_rec, width, sources, tuple(calibrators), run_metadata, str(path), rec_std,
        shared,
    )


def _basis(obj: Any, path: PathLike, prefix: str = "") -> PolynomialBasis:
    try:
        return PolynomialBasis(
            attr_text(_attr(obj, f"{prefix}kind", path)),  # type: ignore[arg-type]
            float(_attr(obj, f"{prefix}f_lo_hz", path)),
            float(_attr(obj, f"{prefix}f_hi_hz", path)),
        )
    except ValueError as err:
        raise FileFormatError(f"{path}: bad basis on '{obj.name}': {err}") from err


def _orders(value: NDArray[Any], path: PathLike) -> Orders:
    bad = value.shape != (N_PARAMETERS,) or value.dtype.kind not in "iu"
    if bad or np.any(value < 0) or np.any(value > MAX_FILE_ORDER):
        raise FileFormatError(
            f"{path}: orders must be {N_PARAMETERS} integers 0-{MAX_FILE_ORDER}: {value}"
        )
    return as_orders(value.tolist())


def read_truth(path: PathLike) -> ReceiverTruth | None:
    """Read the simulated receiver of a run file (``None`` for a measured run)."""
    with _open(path, RUN_FORMATS) as f:
        if "simulation_truth" not in f:
            return None
        g = _group(f, "simulation_truth", path)
        orders = _orders(_array(g, "orders", path), path)
        coefficients = _array(g, "coefficients", path)
        if coefficients.shape != (sum(orders),):
            raise FileFormatError(f"{path}: simulation_truth coefficients do not match orders")
        params = PolynomialParameters(_basis(g, path, "basis_"), orders, coefficients)
        gain, offset = (tuple(float(v) for v in _array(g, k, path)) for k in _TRUTH_TUPLES)
        if not all(np.all(np.isfinite(v)) for v in (coefficients, gain, offset)):
            raise FileFormatError(f"{path}: simulation_truth holds NaN or infinite numbers")
        return ReceiverTruth(params, gain, offset)
