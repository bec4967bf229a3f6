"""Simulated data sets shared by the tests (thesis section 4.2 set-ups)."""

from dataclasses import replace

import numpy as np

from calibration import CalibrationData
from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run

#: Thesis 4.2.1: constant noise-wave parameters (K).
CONSTANT_TRUTH = {"unc": [250.0], "cos": [190.0], "sin": [90.0], "NS": [1200.0], "L": [298.0]}

#: Thesis 4.2.3: second-order polynomials in the normalised frequency x (K), power-series
#: coefficients; x spans [-1, 1] over the band (our reading of "normalised frequency").
SECOND_ORDER_TRUTH = {
    "unc": [250.0, -3.0, 1.0],
    "cos": [190.0, 0.0, 2.0],
    "sin": [90.0, 8.0, 3.0],
    "NS": [1200.0, 5.0, 4.0],
    "L": [298.0, 10.0, 5.0],
}

#: Thesis table 4.1 order, in pairs, mapped onto the REACH sources.
TABLE_4_1_ORDER = ("cold", "hot", "c10r10", "c10r250", "c2r27", "c2r91", "r25", "r100")


def thesis_style_run(
    truth: dict[str, list[float]],
    calibrators: tuple[str, ...],
    seed: int,
    sigma_k: float = 1.0,
    channel_factor: int = 16,
) -> tuple[CalibrationData, object]:
    """Noiseless spectra, Gaussian noise of ``sigma_k`` on the calibrator temperatures.

    This is the thesis's idealised noise model of sections 4.2.1-4.2.3 (noise added to
    T_cal "to conserve its Gaussian form"), under which its solver's likelihood is exact.
    """
    cfg = SimulationConfig(
        channel_width_hz=ITPM_CHANNEL_WIDTH_HZ * channel_factor,
        calibrators=calibrators,
        radiometer_noise=False,
        truth_coefficients={
            name: [float(c) for c in np.polynomial.legendre.poly2leg(coeffs)]
            for name, coeffs in truth.items()
        },
        t_ambient_k=298.0,
        t_hot_k=373.0,
    )
    run = simulate_run(cfg, rng=seed)
    rng = np.random.default_rng(seed + 1000)
    sources = {
        name: replace(
            src, temperature_k=src.temperature_k + sigma_k * rng.standard_normal(src.gamma.size)
        )
        for name, src in run.data.sources.items()
    }
    return replace(run.data, sources=sources), run.truth


def with_exact_reflections(data: CalibrationData, physics) -> CalibrationData:
    """``data`` with the reflections the simulated receiver's VNA would read without error.

    ``physics`` is the simulated receiver's (:class:`reach_receiver.sim.physics.ReceiverPhysics`):
    the receiver's own reflection and each source's at the VNA's reference plane.
    """
    freq = data.freq_hz
    at_vna = physics.config.effects.at_vna
    return replace(
        data,
        gamma_rec=physics.reflection("lna", freq),
        sources={name: replace(source, gamma=at_vna(physics.reflection(name, freq), freq))
                 for name, source in data.sources.items()},
    )
