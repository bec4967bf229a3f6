"""The site file's calibration corrections: which two-ports, cables and thermocouples.

Keys of the site's ``calibration`` section beside ``band_hz`` (issue 14, item 6)::

    calibration:
      band_hz: [50.0e+6, 130.0e+6]
      solver: radiometric      # the calibrate step's default (site.py, calibration.solve.solvers)
      mts: {sources: mts_j1_j2.s2p, lna: mts_j2_j4.s2p}   # two-ports, port 1 at the device
      cables:                  # sources with a cable at its own temperature (eqs. 4.8-4.9)
        hot: {length_m: 0.3, velocity_factor: 0.83, loss_db_per_m: 0.1, thermocouple: 1}
        c10r10: {s2p: cable_10m.s2p, thermocouple: 6}
      rfi: true                # flag spikes and drop their channels before the solve

``mts.sources`` is the switch path between the sources and the VNA (de-embedded from each
source's S11, eq. 4.6), ``mts.lna`` the path between the LNA (port 1) and the sources
(embedded onto the LNA's S11, eq. 4.7). A cable is a measured two-port (``s2p``, port 1
at the termination) or a data-sheet coax (``length_m``, ``velocity_factor``,
``loss_db_per_m`` at ``ref_freq_hz``, default 100 MHz, scaled by ``(f/f_ref)^
loss_exponent``, default 0.5: :class:`calibration.rf.coax.DataSheetCoax`); ``thermocouple``
is the TC-08 port on the cable, the termination's being the source's own (the site's
``thermocouples``). Relative file names are taken from the site file's directory.

Every Touchstone file the site names (these two-ports, the ``references``) is checked when
the site is read (:func:`touchstone_problem`): a file that exists must be a regular file
of at most :data:`MAX_TOUCHSTONE_BYTES` that parses with the expected number of ports, so
that a device, a FIFO, a huge or a foreign file is named at its site-file line instead of
failing (or filling memory) in the middle of a run. A file not there yet is not refused:
a site is often checked before its files are installed.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .fields import REQUIRED, Fields

#: The largest Touchstone file a site may name: a network of ~10^5 frequencies.
MAX_TOUCHSTONE_BYTES = 8 * 1024 * 1024

CALIBRATION_KEYS = ("band_hz", "band_of_interest_hz", "solver", "mts", "cables", "rfi")
_MTS_KEYS = ("sources", "lna")
_COAX_KEYS = ("length_m", "velocity_factor", "loss_db_per_m", "ref_freq_hz", "loss_exponent")
_CABLE_KEYS = ("thermocouple", "s2p", *_COAX_KEYS)


@dataclass(frozen=True)
class CableSettings:
    """A source's cable: its model (``s2p`` or a data-sheet coax) and its TC-08 port."""

    thermocouple: int
    s2p: str | None = None
    length_m: float | None = None
    velocity_factor: float | None = None
    loss_db_per_m: float | None = None
    ref_freq_hz: float = 100e6
    loss_exponent: float = 0.5


@dataclass(frozen=True)
class CorrectionSettings:
    """The site's corrections (module doc); none by default."""

    mts_sources: str | None = None
    mts_lna: str | None = None
    cables: Mapping[str, CableSettings] = field(default_factory=dict)
    rfi: bool = False

    def path(self, name: str, site_source: str) -> Path:
        """A file named in the site, relative to the site file's directory."""
        return site_path(name, site_source)


def site_path(name: str, site_source: str) -> Path:
    """A file named in a site file: relative names are taken from the site's directory."""
    given = Path(name)
    base = Path(site_source).parent if site_source not in ("", "<memory>") else Path()
    return given if given.is_absolute() else base / given


def touchstone_problem(path: Path, ports: int) -> str | None:
    """What is wrong with a Touchstone file a site names (module doc), ``None`` if nothing."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as err:
        return f"{path}: {err.strerror or err}"
    if not stat.S_ISREG(info.st_mode):
        return f"{path} is not a regular file"
    if info.st_size > MAX_TOUCHSTONE_BYTES:
        return f"{path} is {info.st_size} bytes: a Touchstone file has at most " + str(
            MAX_TOUCHSTONE_BYTES
        )
    # Imported here: numpy is a fifth of a second, which a site file without corrections
    # (every reach-run status) need not pay.
    from calibration.rf.touchstone import read_touchstone_network

    try:
        network = read_touchstone_network(path)
    except (OSError, ValueError) as err:  # TouchstoneError is a ValueError
        return str(getattr(err, "strerror", None) or err)
    if network.n_ports != ports:
        return f"{path}: a {network.n_ports}-port file, where a {ports}-port one is needed"
    return None


def _checked_file(f: Fields, name: str, ports: int) -> str | None:
    """A Touchstone file named at key ``name`` of ``f``, checked (problems go to ``f``)."""
    value = f.text(name, None)
    if value is not None:
        problem = touchstone_problem(site_path(value, f.file), ports)
        if problem is not None:
            f.report(name, problem)
            return None
    return value


def read_corrections(f: Fields) -> CorrectionSettings:
    """The corrections of a site's ``calibration`` section (problems go to ``f``)."""
    mts = f.mapping("mts", _MTS_KEYS)
    sources = _checked_file(mts, "sources", 2) if mts is not None else None
    lna = _checked_file(mts, "lna", 2) if mts is not None else None
    cables: dict[str, CableSettings] = {}
    listed = f.raw("cables", None)
    if listed is not None and not isinstance(listed, Mapping):
        f.report("cables", "must map source names to their cables")
    names = tuple(str(k) for k in listed) if isinstance(listed, Mapping) else ()
    cable = f.mapping("cables", names) if names else None
    for name in names:
        section = cable.mapping(name, _CABLE_KEYS) if cable is not None else None
        if section is not None:
            read = _cable(section)
            if read is not None:
                cables[name] = read
    rfi = f.raw("rfi", False)
    if not isinstance(rfi, bool):
        f.report("rfi", f"must be true or false, not {rfi!r}")
        rfi = False
    return CorrectionSettings(mts_sources=sources, mts_lna=lna, cables=cables, rfi=rfi)


def _cable(f: Fields) -> CableSettings | None:
    port = f.count("thermocouple", REQUIRED)
    if f.has("thermocouple") and not 1 <= port <= 8:
        f.report("thermocouple", f"must be a TC-08 port 1-8, not {port}")
    s2p = _checked_file(f, "s2p", 2)
    coax = [k for k in _COAX_KEYS if f.has(k)]
    if s2p is not None and coax:
        f.report("s2p", f"give a measured two-port or a data-sheet cable, not both ({coax})")
    length = velocity = loss = None
    if not f.has("s2p"):  # a data-sheet cable (a bad s2p is already reported)
        length = f.number("length_m", REQUIRED, low=0.0, open_low=True)
        velocity = f.number("velocity_factor", REQUIRED, low=0.0, high=1.0, open_low=True)
        loss = f.number("loss_db_per_m", REQUIRED, low=0.0)
    ref = f.number("ref_freq_hz", 100e6, low=0.0, open_low=True)
    exponent = f.number("loss_exponent", 0.5, low=0.0, high=2.0)
    if f.failed:
        return None
    return CableSettings(port, s2p, length, velocity, loss, ref, exponent)


def corrections_yaml(settings: CorrectionSettings) -> dict[str, Any]:
    """The ``calibration`` keys that reproduce ``settings`` (empty for none)."""
    out: dict[str, Any] = {}
    mts = {"sources": settings.mts_sources, "lna": settings.mts_lna}
    if any(mts.values()):
        out["mts"] = {k: v for k, v in mts.items() if v is not None}
    if settings.cables:
        out["cables"] = {
            name: {
                k: v
                for k, v in vars(cable).items()
                if v is not None and (k, v) not in (("ref_freq_hz", 100e6), ("loss_exponent", 0.5))
            }
            for name, cable in settings.cables.items()
        }
    if settings.rfi:
        out["rfi"] = True
    return out
