"""Spectra kinds: one integration of a source, and Dicke cycles.

==================  =====================================================================
``spectrum``        ``{source: ant, seconds: 600}``: one integration, no Dicke switching
``dicke``           ``{sources: [hot, cold], seconds: 600}``: per position, for each source
==================  =====================================================================

Seconds become a count of spectra at the site's accumulation period
(``devices.spectrometer.period_s``), the same period the dry run's timing uses. Every
record keeps the time (UTC, Unix seconds) and local sidereal time of each spectrum it
averaged, beside the average itself.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration.core.sidereal import apparent_lst_h
from reach_receiver.config.fields import Fields
from reach_receiver.errors import ReceiverError
from reach_receiver.frontend.layout import NOISE_SOURCE, REFERENCE_LOAD
from reach_receiver.schedule.parsing import ParseContext
from reach_receiver.schedule.steps import Step, Where
from reach_receiver.schedule.timing import TimingWalk, hms

from ..context import RunContext
from ..kind import RunnableKind
from ..measure import (
    DICKE_POSITIONS,
    DICKE_REFERENCES,
    DickeCycle,
    integrate_connected,
    source_temperature,
    take_dicke_cycle,
)


def lst_of_spectra(run: RunContext, starts: tuple[float, ...]) -> list[float]:
    """The LST (hours) at the middle of each spectrum that starts at ``starts``."""
    middles = np.asarray(starts, dtype=float) + 0.5 * run.period_s
    return [float(h) for h in apparent_lst_h(middles, run.site.longitude_deg)]


def dicke_cycle(run: RunContext, source: str, seconds: float, label: str = "") -> int:
    """Take one Dicke cycle of ``source`` and store it; return its measurement number.

    The source's temperature is the mean of its thermocouple (the site's table 2.2)
    during its own position, with its standard error
    (:func:`~reach_receiver.run.measure.source_temperature`). ``label`` says where the
    cycle stands in its step (``2/12``) in progress reports.
    """
    devices = run.instruments
    n = run.n_spectra(seconds)
    where = f" ({label})" if label else ""

    def progress(position: str, done: int, total: int) -> None:
        run.stop.check()
        positions_after = len(DICKE_POSITIONS) - 1 - DICKE_POSITIONS.index(position)
        left = (total - done + positions_after * (n + 2)) * run.period_s
        run.progress.update(f"Dicke {source}{where}: {position}", done, total, left)

    cycle = take_dicke_cycle(
        devices.frontend, devices.spectrometer, source, n, run.temperatures, progress=progress,
        between=run.safe_point,
    )
    temperature, temperature_std = source_temperature(cycle, run.site.thermocouples.get(source))
    connects = {"source": source, **DICKE_REFERENCES}
    number = run.store.add_dicke(
        source,
        spectra={k: v.mean for k, v in cycle.spectra.items()},
        timestamps={k: v.timestamps for k, v in cycle.spectra.items()},
        lst_h={k: lst_of_spectra(run, v.timestamps) for k, v in cycle.spectra.items()},
        integration_s=dict(cycle.integration_s),
        n_spectra={k: v.n_spectra for k, v in cycle.spectra.items()},
        temperature_k=temperature,
        temperature_std_k=temperature_std,
        switch_states={
            k: {"connected": connects[k], **cycle.switch_states.get(k, {})} for k in cycle.spectra
        },
        counters={
            k: {
                "packets_lost": v.packets_lost,
                "heaps_dropped": v.heaps_dropped,
                "repeats": cycle.repeats.get(k, 0),
            }
            for k, v in cycle.spectra.items()
        },
        timestamp=run.clock.now(),
        thermocouples_k=port_temperatures(cycle),
    )
    run.flush_temperatures()
    return number


def port_temperatures(cycle: DickeCycle) -> dict[int, float]:
    """Every TC-08 port's mean during the source position (K); unread ports left out."""
    found = {}
    for port in range(1, 9):
        try:
            found[port] = cycle.temperature_k(port)
        except (ReceiverError, KeyError):
            continue
    return found


def dicke_connections(sources: tuple[str, ...]) -> list[tuple[str, str]]:
    """A Dicke cycle's connections: each source, the reference load, the noise source."""
    return [(x, "lna") for src in sources for x in (src, REFERENCE_LOAD, NOISE_SOURCE)]


# --------------------------------------------------------------------------- spectrum
@dataclass(frozen=True)
class MeasureSpectrum(Step):
    """Integrate one source for ``seconds`` (no Dicke switching)."""

    source: str
    seconds: float


class MeasureSpectrumKind(RunnableKind[MeasureSpectrum]):
    """``spectrum``."""

    name = "spectrum"
    step_type = MeasureSpectrum
    keys = ("source", "seconds")

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> MeasureSpectrum:
        """``source`` and ``seconds`` (at least one spectrum)."""
        source = f.choice("source", ctx.sources) or ""
        return MeasureSpectrum(where, source, ctx.integration(f, "seconds"))

    def describe(self, step: MeasureSpectrum) -> str:
        """Source and duration."""
        return f"spectrum of {step.source} for {hms(step.seconds)}"

    def duration(self, step: MeasureSpectrum, walk: TimingWalk) -> float:
        """One integration."""
        return walk.spectra(1, step.seconds)

    def connections(self, step: MeasureSpectrum) -> list[tuple[str, str]]:
        """The source to the LNA."""
        return [(step.source, "lna")]

    def rest(
        self, step: MeasureSpectrum, measured: Sequence[tuple[str, str]]
    ) -> MeasureSpectrum | None:
        """Nothing once its spectrum is stored."""
        return None if ("spectrum", step.source) in measured else step

    def execute(self, step: MeasureSpectrum, run: RunContext) -> None:
        """Integrate and store, with each spectrum's time and LST.

        An integration during which the front-end moved is taken again
        (:func:`~reach_receiver.run.measure.integrate_connected`).
        """
        devices = run.instruments
        n = run.n_spectra(step.seconds)
        report = run.spectrum_progress(f"spectrum of {step.source}", run.period_s)
        taken = integrate_connected(
            devices.frontend,
            devices.spectrometer,
            step.source,
            n,
            on_spectrum=report,
            label=f"spectrum of {step.source}",
        )
        acc, state = taken.spectrum, taken.state
        run.store.add_spectrum(
            step.source,
            acc.mean,
            timestamps=acc.timestamps,
            lst_h=lst_of_spectra(run, acc.timestamps),
            integration_s=acc.n_spectra * run.period_s,
            switch_state=state.as_pins(),
            timestamp=run.clock.now(),
        )


# --------------------------------------------------------------------------- dicke
@dataclass(frozen=True)
class Dicke(Step):
    """A Dicke cycle of each source: source, reference load, noise source, ``seconds`` each."""

    sources: tuple[str, ...]
    seconds: float


class DickeKind(RunnableKind[Dicke]):
    """``dicke``."""

    name = "dicke"
    step_type = Dicke
    keys = ("sources", "seconds")

    def parse(self, f: Fields, where: Where, ctx: ParseContext) -> Dicke:
        """``sources`` and ``seconds`` per position (at least one spectrum)."""
        sources = f.names("sources", ctx.sources, "source")
        return Dicke(where, tuple(sources), ctx.integration(f, "seconds"))

    def describe(self, step: Dicke) -> str:
        """Sources and duration per position."""
        return f"Dicke cycles of {', '.join(step.sources)}, {hms(step.seconds)} per position"

    def duration(self, step: Dicke, walk: TimingWalk) -> float:
        """Three integrations per source."""
        return walk.spectra(3 * len(step.sources), step.seconds)

    def connections(self, step: Dicke) -> list[tuple[str, str]]:
        """Each source's three positions."""
        return dicke_connections(step.sources)

    def rest(self, step: Dicke, measured: Sequence[tuple[str, str]]) -> Dicke | None:
        """The sources whose cycle is not stored yet."""
        done = {name for kind, name in measured if kind == "dicke"}
        left = tuple(s for s in step.sources if s not in done)
        return dataclasses.replace(step, sources=left) if left else None

    def execute(self, step: Dicke, run: RunContext) -> None:
        """A Dicke cycle of each source, stored as soon as it is complete."""
        for index, source in enumerate(step.sources):
            dicke_cycle(run, source, step.seconds, f"{index + 1}/{len(step.sources)}")
