"""A Dicke run of the simulated receiver's physics straight into the engine's data.

:class:`~reach_receiver.sim.receiver.SimulatedReceiver` runs the instruments (the Teensy,
the VNA, the iTPM, the TC-08) against :class:`~reach_receiver.sim.physics.
ReceiverPhysics` in real threads on a compressed clock; a run through it takes tens of
seconds, and a starved machine can put a spectrum or a reading late (the iTPM skips, the
TC-08 file goes stale while the heated load wanders). This module takes the same physics
at one instant and builds what the run layer hands the engine
(:func:`reach_receiver.store.handover.select`): per source the three Dicke spectra with
radiometer noise ``sigma_P = P / sqrt(B tau)`` (thesis eq. 2.3) and, with
:mod:`~reach_receiver.sim.effects` ``rfi`` on, the spikes of ``n_spectra`` averaged
spectra; the reflections as the VNA reads them (through the MTS's VNA path, with
circular complex trace noise of rms ``vna_sigma`` per channel, 0 by default); every
calibrator's temperature and every TC-08 port as the thermocouples read them. It is the
engine-level path of the corrections' test and benchmark: fast, and free of the
instruments' timing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from calibration.model.data import CalibrationData, Integration, SourceData
from calibration.model.simulate import REACH_CALIBRATORS
from reach_receiver.frontend.layout import NOISE_SOURCE, REFERENCE_LOAD
from reach_receiver.store.handover import ANTENNA, HandOver, band_channels

from .physics import KELVIN_AT_0C, ReceiverPhysics

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class EngineRun:
    """The engine's view of one simulated run: calibrators, the antenna, the hand-over."""

    data: CalibrationData
    others: dict[str, SourceData]
    handover: HandOver


def channels(
    physics: ReceiverPhysics, band_hz: tuple[float, float], stride: int
) -> NDArray[np.int_]:
    """Every ``stride``-th channel of the band, and every channel an RFI line falls in."""
    width = physics.config.channel_width_hz
    band = band_channels(width, band_hz)
    k = np.arange(band.start, band.stop)
    chosen = (k - band.start) % stride == 0
    if physics.config.effects.rfi:
        lines = [round(f / width) for f in physics.config.effects.rfi_channels_hz]
        chosen |= np.isin(k, lines)
    return k[chosen]


def engine_run(
    physics: ReceiverPhysics,
    rng: np.random.Generator,
    *,
    seconds: float = 600.0,
    n_spectra: int = 5,
    stride: int = 1,
    band_hz: tuple[float, float] = (50e6, 130e6),
    vna_sigma: float = 0.0,
    calibrators: tuple[str, ...] = REACH_CALIBRATORS,
) -> EngineRun:
    """The calibrators and the antenna, ``seconds`` per Dicke position, at the physics' start.

    ``stride`` keeps every ``stride``-th channel of the band (each still of the
    spectrometer's width and noise); :func:`channels` says which.
    """
    effects = physics.config.effects
    t = physics.clock.now()
    k = channels(physics, band_hz, stride)
    freq = np.asarray(physics.freq_hz[k], dtype=float)
    width = physics.config.channel_width_hz
    radiometer = 1.0 / np.sqrt(width * seconds)
    every_channel = np.asarray(physics.freq_hz, dtype=float)

    def measured(p_full: FloatArray) -> FloatArray:
        draws = rng.exponential(size=(n_spectra, len(effects.rfi_channels_hz)))
        spikes = np.mean([effects.spikes(every_channel, d) for d in draws], axis=0)
        p = (p_full * (1.0 + spikes))[k]
        return np.asarray(p * (1.0 + radiometer * rng.standard_normal(p.shape)), dtype=float)

    def read_by_vna(gamma: NDArray[np.complex128]) -> NDArray[np.complex128]:
        noise = rng.standard_normal(gamma.shape) + 1j * rng.standard_normal(gamma.shape)
        return np.asarray(gamma + vna_sigma * noise / np.sqrt(2), dtype=complex)

    thermocouples = {p: c + KELVIN_AT_0C for p, c in enumerate(physics.thermocouples_c(t))}
    p_load = physics.noiseless_power(REFERENCE_LOAD, t)
    p_ns = physics.noiseless_power(NOISE_SOURCE, t, ns_on=True)
    integration = Integration(seconds, seconds, seconds)
    sources: dict[str, SourceData] = {}
    temperatures: dict[str, float] = {}
    for name in (*calibrators, ANTENNA):
        gamma = read_by_vna(effects.at_vna(physics.reflection(name, freq), freq))
        temperature = None
        if name != ANTENNA:
            temperatures[name] = thermocouples[physics.thermocouple_of(name)]
            temperature = np.full(freq.shape, temperatures[name])
        sources[name] = SourceData(
            name,
            gamma,
            measured(physics.noiseless_power(name, t)),
            measured(p_load),
            measured(p_ns),
            integration,
            temperature,
        )
    data = CalibrationData(
        freq_hz=freq,
        gamma_rec=read_by_vna(physics.reflection("lna", freq)),
        sources={n: s for n, s in sources.items() if n != ANTENNA},
        channel_width_hz=width,
        metadata={"simulated": True},
    )
    handover = HandOver(
        band_hz=band_hz,
        channel_width_hz=width,
        cycles={},
        s11={},
        calibrators=calibrators,
        temperatures_k=temperatures,
        thermocouples_k={n: thermocouples for n in sources},
    )
    return EngineRun(data, {ANTENNA: sources[ANTENNA]}, handover)
