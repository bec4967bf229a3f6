"""A simulated receiver for adaptive runs: repeated Dicke cycles of a source, averaged.

Each measurement of ``t`` seconds per Dicke position is drawn from the truth with that
integration (:func:`calibration.model.simulate.simulate_source`) and averaged with the
source's earlier ones weighted by integration time, the times added::

    P = sum_k t_k P_k / sum_k t_k,      tau = sum_k t_k

which is what one spectrum integrated ``tau`` seconds would be: its radiometer noise is
``P / sqrt(B tau)``, the variance the engine derives from ``tau`` (eq. 3.9). A plain mean of
cycles of unequal length would have a larger variance than ``tau`` implies.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..model.data import CalibrationData, Integration, SourceData
from ..model.reflections import reach_source_reflection
from ..model.simulate import SimulatedRun, SimulationConfig, simulate_run, simulate_source


@dataclass
class SimulatedReceiver:
    """The simulator's truth and set-up, measured one Dicke cycle at a time.

    ``run`` (:func:`simulate_run`'s, its spectra unused) holds the truth, the receiver's
    measured reflection and the noiseless antenna; :meth:`measure` adds a cycle;
    :meth:`data` is the calibrators measured so far, as the hand-over gives them.
    """

    config: SimulationConfig
    rng: np.random.Generator
    run: SimulatedRun = field(init=False)
    sources: dict[str, SourceData] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.run = simulate_run(self.config, rng=self.rng)

    @property
    def antenna_s11(self) -> np.ndarray:
        """The antenna's reflection over the channels."""
        return np.asarray(self.run.validation_noiseless.gamma)

    def antenna(self, temperature_k: float | np.ndarray) -> SourceData:
        """The antenna (the simulator's ``ant`` reflection) at ``temperature_k``, noiseless.

        ``temperature_k``: one temperature, or one per channel (a sky's power law).
        """
        c, freq = self.config, self.run.data.freq_hz
        return simulate_source(
            "ant", freq, reach_source_reflection("ant", freq), self.run.gamma_rec_true,
            temperature_k, self.run.truth, Integration(1.0, 1.0, 1.0), c.channel_width_hz, None,
            known_temperature=False,
        )

    def measure(self, name: str, seconds: float) -> None:
        """One Dicke cycle of ``name``, ``seconds`` per position, averaged in."""
        c, freq = self.config, self.run.data.freq_hz
        new = simulate_source(
            name, freq, reach_source_reflection(name, freq), self.run.gamma_rec_true,
            c.temperature_k(name), self.run.truth, Integration(seconds, seconds, seconds),
            c.channel_width_hz, self.rng,
        )
        measured = self.run.data.sources[name]  # one S11 per source, VNA noise and all
        new = replace(new, gamma=measured.gamma, gamma_std=measured.gamma_std)
        old = self.sources.get(name)
        if old is None:
            self.sources[name] = new
            return
        a, b = old.integration.source_s, seconds
        self.sources[name] = replace(
            old,
            p_source=(a * old.p_source + b * new.p_source) / (a + b),
            p_load=(a * old.p_load + b * new.p_load) / (a + b),
            p_ns=(a * old.p_ns + b * new.p_ns) / (a + b),
            integration=Integration(a + b, a + b, a + b),
        )

    def data(self) -> CalibrationData:
        """The calibrators measured so far (in the set-up's order)."""
        names = [n for n in self.config.calibrators if n in self.sources]
        return replace(self.run.data, sources={n: self.sources[n] for n in names})
