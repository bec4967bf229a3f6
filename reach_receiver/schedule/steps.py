"""The compiled form of a schedule: frozen step objects, each knowing where it was written.

A YAML schedule (``schedules/*.yaml``) is checked and compiled (:mod:`.compile`) into a
:class:`Schedule` holding a tuple of these steps; the runner (:mod:`.runner`) executes
them. Nothing here does I/O. Every step carries its :class:`Where` (file and line) so
that a failure at run time names the line of the schedule that asked for it.

Steps, as written in YAML (one single-key mapping per step):

===================  ====================================================================
``initialise``       connect every device, safe state, switch on ``rails``
``power``            switch rails on or off: ``{12v: on, fan: off}``
``connect``          ``{source: hot, to: lna}`` (``to``: ``lna`` or ``vna``)
``vna_calibrate``    one-port SOL with the MS2 standards; sweep settings may be given
``test_load_check``  measure MS2-6 and compare with a reference Touchstone file
``s11``              ``{targets: [hot, cold, lna]}``
``spectrum``         ``{source: ant, seconds: 600}``: one integration, no Dicke switching
``dicke``            ``{sources: [hot, cold], seconds: 600}``: per position
``temperatures``     ``{period_s: 10}``: (re)start background thermocouple logging
``tec``              ``{setpoint_c: 25, wait: {tolerance_c: 0.1, hold_s: 300, timeout_s: 7200}}``
``wait``             ``{seconds: 60}``, ``{until_utc: "2026-11-22T18:00Z"}``, ``{until_lst_h: 4.5}``
``repeat``           ``{count: 4, period_s: 3600, steps: [...]}``
``calibrate``        solve the data so far; compare with a benchmark solution
``observe``          antenna Dicke cycles with periodic test-load checks, RFI flags, calibration
``safe``             the front-end's safe state
===================  ====================================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Literal


@dataclass(frozen=True)
class Where:
    """Where a step or value was written: file and 1-based line."""

    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass(frozen=True)
class Step:
    """Base of every step."""

    where: Where


@dataclass(frozen=True)
class Initialise(Step):
    """Connect the devices, put the front-end in its safe state, then power ``rails``."""

    rails: tuple[str, ...] = ("12v", "24v", "6v", "fan", "tec")


@dataclass(frozen=True)
class Power(Step):
    """Switch rails: ``states`` maps rail name to on (True) or off."""

    states: tuple[tuple[str, bool], ...]


@dataclass(frozen=True)
class Connect(Step):
    """Connect a source (or ``lna``, or a VNA standard) to the LNA or the VNA."""

    source: str
    to: Literal["lna", "vna"] = "lna"


@dataclass(frozen=True)
class Sweep:
    """VNA sweep settings; ``None`` keeps the driver's default (REACH's)."""

    f_start_hz: float | None = None
    f_stop_hz: float | None = None
    points: int | None = None
    ifbw_hz: float | None = None
    power_dbm: float | None = None
    averages: int | None = None


@dataclass(frozen=True)
class VnaCalibrate(Step):
    """Configure the sweep and run a one-port SOL calibration with the MS2 standards."""

    sweep: Sweep = field(default_factory=Sweep)


@dataclass(frozen=True)
class TestLoadCheck(Step):
    """Compare the MS2-6 test load with a reference; recalibrate up to ``retries`` times.

    ``reference`` ``None`` takes the site file's ``references.test_load``. The check
    passes when the ``statistic`` (``max``, ``p95`` or ``rms``) over frequency of
    ``|S11 - S11_ref| / |S11_ref|`` is at most ``tolerance`` (thesis 2.1.1: 5 %).
    """

    __test__ = False  # not a pytest class, whatever its name

    reference: Path | None = None
    tolerance: float = 0.05
    statistic: Literal["max", "p95", "rms"] = "p95"
    retries: int = 2


@dataclass(frozen=True)
class MeasureS11(Step):
    """Measure the reflection of each target (a source name or ``lna``)."""

    targets: tuple[str, ...]


@dataclass(frozen=True)
class MeasureSpectrum(Step):
    """Integrate one source for ``seconds`` (no Dicke switching)."""

    source: str
    seconds: float


@dataclass(frozen=True)
class Dicke(Step):
    """A Dicke cycle of each source: source, reference load, noise source, ``seconds`` each."""

    sources: tuple[str, ...]
    seconds: float


@dataclass(frozen=True)
class Temperatures(Step):
    """(Re)start background thermocouple logging every ``period_s``."""

    period_s: float = 10.0


@dataclass(frozen=True)
class WaitStable:
    """How the TEC step waits for the enclosure to settle."""

    tolerance_c: float = 0.1
    hold_s: float = 300.0
    timeout_s: float = 7200.0


@dataclass(frozen=True)
class Tec(Step):
    """Set the enclosure's temperature; optionally wait until it is stable."""

    setpoint_c: float
    wait: WaitStable | None = None


@dataclass(frozen=True)
class Wait(Step):
    """Wait a duration, until a UTC time, or until a local sidereal time (hours)."""

    seconds: float | None = None
    until_utc: datetime | None = None
    until_lst_h: float | None = None


@dataclass(frozen=True)
class Repeat(Step):
    """Run ``steps`` ``count`` times, starting a repetition every ``period_s`` if given."""

    count: int
    steps: tuple[Step, ...]
    period_s: float | None = None


@dataclass(frozen=True)
class Calibrate(Step):
    """Solve the noise-wave parameters from the data taken so far.

    With a ``benchmark`` solution file, the new solution is verified against it: every
    parameter's band-averaged value within ``tolerance`` (thesis 2.1.3: 5 %).
    """

    benchmark: Path | None = None
    tolerance: float = 0.05
    f_lo_hz: float = 50e6
    f_hi_hz: float = 130e6


@dataclass(frozen=True)
class Observe(Step):
    """Antenna Dicke cycles, a test-load check every ``test_load_every`` cycles, RFI flags."""

    cycles: int
    seconds: float
    source: str = "ant"
    test_load_every: int = 6
    rfi_threshold_sigma: float = 5.0


@dataclass(frozen=True)
class Safe(Step):
    """Put the front-end in its safe state."""


@dataclass(frozen=True)
class Schedule:
    """A compiled schedule: its steps and everything needed to record how it was made."""

    name: str
    steps: tuple[Step, ...]
    files: tuple[tuple[str, str], ...]  # (path, text) of the schedule and its includes
    variables: tuple[tuple[str, object], ...] = ()
