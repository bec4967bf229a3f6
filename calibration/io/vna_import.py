"""Raw VNA exports with their standards: corrected reflection coefficients of every device.

A laboratory exports, as one-port Touchstone files, the *uncorrected* readings of the
calibration standards (short, open, load) and of each device (a load, the receiver).
Per device, the standards' readings and the kit's actual reflections give the three error
terms of the port (:func:`calibration.rf.one_port.solve_one_port`, eq. 2 there), and the
device's reading is corrected by eq. 3 there::

    G = (m - e00) / (e01e10 + e11 (m - e00))

The kit is ideal (short ``-1``, open ``+1``, load ``0``) or a Keysight-style description
(:mod:`calibration.rf.cal_kit`), read from JSON by :func:`read_cal_kit`. File names are
patterns (:class:`VnaLayout`): ``{name}`` is the device, shell wildcards are allowed, and
each pattern must match one file. Standards shared by every device
(``cal_short.s1p``), taken with each device (``{name}/Short01.s1p``, as edges-io lays
out EDGES-2 runs), or given per device (EDGES-3's ``*_lna_S.s1p`` for the receiver) are
all patterns.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..core.errors import FileFormatError, InvalidDataError
from ..rf.cal_kit import (
    IDEAL_KIT,
    STANDARD_NAMES,
    CalKit,
    LoadStandard,
    Offset,
    OpenStandard,
    ShortStandard,
)
from ..rf.kit_format import KIT_EXAMPLE, KIT_FORMAT
from ..rf.one_port import OnePortTerms, solve_one_port
from ..rf.touchstone import read_touchstone
from .edges_import import find_file

__all__ = [
    "KIT_EXAMPLE",
    "KIT_FORMAT",
    "VnaLayout",
    "check_receiver_plane",
    "correct_exports",
    "read_cal_kit",
]

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]
Reflection = tuple[FloatArray, ComplexArray]
_DEFAULT_STANDARDS = {s: f"cal_{s}.s1p" for s in STANDARD_NAMES}


@dataclass(frozen=True)
class VnaLayout:
    """Patterns, relative to the export directory, of the devices' and standards' files.

    ``standards`` maps ``short``, ``open``, ``load`` to a pattern (``{name}`` allowed);
    ``per_device`` replaces them for the named devices.
    """

    device: str = "{name}.s1p"
    standards: Mapping[str, str] = field(default_factory=lambda: dict(_DEFAULT_STANDARDS))
    per_device: Mapping[str, Mapping[str, str]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for who, patterns in (("", self.standards), *self.per_device.items()):
            if set(patterns) != set(STANDARD_NAMES):
                owner = f" for {who!r}" if who else ""
                raise InvalidDataError(
                    f"standards{owner} must be exactly {', '.join(STANDARD_NAMES)}; "
                    f"got {', '.join(patterns) or 'none'}"
                )

    def standards_of(self, name: str) -> tuple[str, ...]:
        """The standards' patterns of device ``name``, in :data:`STANDARD_NAMES` order."""
        patterns = self.per_device.get(name, self.standards)
        return tuple(patterns[s] for s in STANDARD_NAMES)


def correct_exports(
    directory: str | Path,
    names: tuple[str, ...],
    layout: VnaLayout | None = None,
    kit: CalKit = IDEAL_KIT,
) -> dict[str, Reflection]:
    """Corrected ``(freq_hz, gamma)`` of every named device, on each device's VNA grid.

    Raises
    ------
    FileFormatError
        A pattern matching no file or several, an unreadable Touchstone file
        (``file:line: message``), or a device measured on another grid than its standards.
    DegenerateStandardsError
        Standards that do not determine the error terms (names the frequencies).
    """
    directory = Path(directory)
    layout = layout or VnaLayout()
    solved: dict[tuple[Path, ...], tuple[FloatArray, OnePortTerms]] = {}
    out: dict[str, Reflection] = {}
    for name in names:
        files = tuple(find_file(directory, p, name) for p in layout.standards_of(name))
        if files not in solved:  # one solve per set of standards
            solved[files] = _error_terms(files, kit)
        freq_std, terms = solved[files]
        device = find_file(directory, layout.device, name)
        freq, raw, _ = read_touchstone(device)
        if freq.shape != freq_std.shape or not np.allclose(freq, freq_std, rtol=1e-12, atol=0):
            raise FileFormatError(
                f"{device}: measured at other frequencies than its standards ({files[0].name})"
            )
        out[name] = (freq, terms.correct(raw))
    return out


def check_receiver_plane(
    layout: VnaLayout, receiver: str, path_given: bool, planes_coincide: bool = False
) -> None:
    """Refuse a receiver read at its own standards' plane with no path to the loads' plane.

    Standards of its own (EDGES-3's ``*_lna_S/O/L.s1p``) put the receiver's corrected
    reflection at another plane than the calibrators'; used as it is, EDGES-3's receiver
    S11 is off by 0.06 (noise scale s^2 of 15.7, leave-one-out errors of 1000+ K). The
    path (:mod:`calibration.io.receiver_path`) must be given, or the planes said to coincide.
    """
    own = layout.standards_of(receiver)
    shared = tuple(layout.standards[s] for s in STANDARD_NAMES)
    if own == shared or path_given or planes_coincide:
        return
    raise InvalidDataError(
        f"the receiver {receiver!r} is read with its own standards ({', '.join(own)}), at "
        "another plane than the loads';\ngive the path between them: --receiver-cable "
        "(EDGES-3: edges3) or --receiver-path FILE.s2p, or --receiver-path none if they coincide"
    )


def _error_terms(files: tuple[Path, ...], kit: CalKit) -> tuple[FloatArray, OnePortTerms]:
    """The port's error terms from the standards' files, in :data:`STANDARD_NAMES` order."""
    readings = [read_touchstone(path) for path in files]
    freq = readings[0][0]
    for path, (f, _, _) in zip(files[1:], readings[1:], strict=True):
        if f.shape != freq.shape or not np.allclose(f, freq, rtol=1e-12, atol=0):
            raise FileFormatError(f"{path}: measured at other frequencies than {files[0]}")
    measured = np.stack([gamma for _, gamma, _ in readings])
    return freq, solve_one_port(measured, kit.reflections(freq), freq)


_KIT_FIELDS: dict[str, tuple[type, tuple[str, ...]]] = {
    "short": (ShortStandard, ("l0", "l1", "l2", "l3")),
    "open": (OpenStandard, ("c0", "c1", "c2", "c3")),
    "load": (LoadStandard, ("resistance_ohm",)),
}
_OFFSET_FIELDS = ("delay_s", "loss_gohm_per_s", "z0_ohm")


def read_cal_kit(path: str | Path) -> CalKit:
    """A calibration kit from JSON, in the data sheet's units (:mod:`calibration.rf.cal_kit`).

    The format (:data:`calibration.rf.kit_format.KIT_FORMAT`), for example::

        {"name": "85033E", "z_ref_ohm": 50,
         "short": {"l0": 2.077, "l1": -108.5, "offset": {"delay_s": 31.8e-12,
                                                        "loss_gohm_per_s": 2.36}},
         "open":  {"c0": 49.43, "c1": -310.1, "offset": {"delay_s": 29.2e-12}},
         "load":  {"resistance_ohm": 50.0}}

    Every standard must be named (``{}`` is an ideal, flush one), so that an empty or
    mistyped file is not taken for the ideal kit; unknown keys are refused (``file: key:
    message``), as is malformed JSON (``file:line: message``).
    """
    try:
        spec = json.loads(Path(path).read_text())
    except json.JSONDecodeError as err:
        raise FileFormatError(f"{path}:{err.lineno}: {err.msg}") from None
    if not isinstance(spec, dict):
        raise FileFormatError(f"{path}: a calibration kit is a JSON object")
    _known(path, "", spec, ("name", "z_ref_ohm", *_KIT_FIELDS))
    kwargs: dict[str, Any] = {}
    for key, (cls, names) in _KIT_FIELDS.items():
        if key in spec:
            kwargs[key] = _standard(path, key, spec[key], cls, names)
    missing = [key for key in _KIT_FIELDS if key not in spec]
    if missing:
        raise FileFormatError(
            f"{path}: no {missing[0]!r} standard (give \"{missing[0]}\": {{}} for an ideal one; "
            "the format: reach-cal import vna --help)"
        )
    try:
        return CalKit(
            **kwargs,
            z_ref_ohm=_number(path, "z_ref_ohm", spec.get("z_ref_ohm", 50.0)),
            name=str(spec.get("name", Path(path).stem)),
        )
    except InvalidDataError as err:
        raise FileFormatError(f"{path}: {err}") from None


def _standard(path: str | Path, key: str, spec: Any, cls: type, names: tuple[str, ...]) -> Any:
    if not isinstance(spec, dict):
        raise FileFormatError(f"{path}: {key}: expected an object")
    _known(path, key, spec, (*names, "offset"))
    values: dict[str, Any] = {n: _number(path, f"{key}.{n}", spec[n]) for n in names if n in spec}
    if "offset" in spec:
        offset = spec["offset"]
        if not isinstance(offset, dict):
            raise FileFormatError(f"{path}: {key}.offset: expected an object")
        _known(path, f"{key}.offset", offset, _OFFSET_FIELDS)
        numbers = {n: _number(path, f"{key}.offset.{n}", offset[n]) for n in offset}
        try:
            values["offset"] = Offset(**numbers)
        except InvalidDataError as err:
            raise FileFormatError(f"{path}: {key}.offset: {err}") from None
    return cls(**values)


def _known(path: str | Path, where: str, spec: dict[str, Any], allowed: tuple[str, ...]) -> None:
    unknown = sorted(set(spec) - set(allowed))
    if unknown:
        prefix = f"{where}: " if where else ""
        raise FileFormatError(
            f"{path}: {prefix}unknown keys {', '.join(unknown)} (known: {', '.join(allowed)})"
        )


def _number(path: str | Path, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise FileFormatError(f"{path}: {key}: expected a number, got {value!r}")
    return float(value)
