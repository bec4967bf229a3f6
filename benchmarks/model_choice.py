"""Model choice over ensembles of truths: the error against the floor and against its report.

Run ``python -m benchmarks.model_choice [--runs N]`` (about 5 minutes at the default 30
runs per ensemble). Each ensemble draws its own truths and runs, seeded; every method
solves the same runs:

* ``fixed 3000K``: the previous default, one fixed 3000 K width, the single best model;
* ``best``: the hierarchical prior (:mod:`calibration.regression.shrinkage`), the single best model;
* ``averaged``: the default, the posterior averaged over models
  (:mod:`calibration.choice.averaging`)
  under a prior scale per parameter fitted to the data (:mod:`calibration.choice.scale_fit`);
* ``shared scale``: averaged too, under one scale shared by the five parameters and
  marginalised (the default until the ensembles were drawn at the data's own sd);
* ``shrink 6``: no choice of orders: six terms of every parameter under the hierarchical
  prior, its scales marginalised (continuous shrinkage in place of dropping terms);
* ``true orders``: the truth's orders fixed, with the fixed wide prior (an oracle: unbiased,
  at the floor, its error bars exact);
* ``own prior`` (random truths only): the ensemble's own prior, another oracle, which
  knows how the truths are drawn: every order combination of 1-6 terms equally likely,
  each higher term Gaussian with the sd of the drawn sizes
  (:class:`~calibration.regression.conjugate.TermPrior`, every model scored and averaged). What a
  method that knew the ensemble could reach on the same runs: a bound the default cannot
  beat on average, and one its own noise may put above the issue's.

Per method: the median and the RMS over runs of (RMS calibration error of the noiseless
validation source) / (Cramer-Rao floor at the true orders); the RMS over runs of
actual / predicted error; and the coverage of the calibration-only 68 % and 95 %
intervals (:meth:`~calibration.solve.solution.CalibratedSpectrum.interval`: for an averaged
solution, the mixture's quantiles; 8 channels a run; with VNA noise, the receiver
reflection's error, which the calibrated noiseless source carries too, is in both the
interval and the floor).
Ensembles of random truths draw each parameter's number of terms from 1 to 6 and each
higher term's size log-uniformly from 0.3 to 30 times the data's own posterior sd (a
pilot fit under the fixed wide prior: :func:`pilot_sd`), so that terms from well below to
well above detectability occur. The quadratic ensemble is the case the issue was
filed on (an independent simulator's): every parameter quadratic across the band, its
quadratic term 1-5 K, at the iTPM's full 6554 channels and 2 minutes a Dicke position.
The last ensemble draws each run's set-up as well (:meth:`Ensemble.draw_setup`): 4-12
calibrators (the cold and hot loads among them), 30 s to 1 h a Dicke position, VNA trace
noise of 1e-3 in half the runs, the truth's sizes in that set-up's own posterior sd.
Under each table,
the default's row is held to the issue's bounds (median <= 1.05, RMS <= 1.10,
actual/predicted 0.9-1.1, coverage 68 +- 3 % and 95 +- 2 %) and the bounds it misses are
named, and its squared error / floor over the true orders' is split by which way its
choice of orders erred, beyond the truth's terms or short of them (:func:`excess_split`).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from calibration.choice.model_fit import OrderChoice
from calibration.core.errors import IllPosedError
from calibration.model.data import CalibrationData
from calibration.model.noise_waves import PARAMETERS
from calibration.model.simulate import (
    ITPM_CHANNEL_WIDTH_HZ,
    REACH_CALIBRATORS,
    SimulationConfig,
    simulate_run,
)
from calibration.regression.conjugate import CoefficientPrior, TermPrior
from calibration.regression.shrinkage import ShrinkagePrior
from calibration.solve.noise_floor import noise_floor
from calibration.solve.radiometric_solver import RadiometricPrior, solve_radiometric
from calibration.solve.solution import Solution

LEVELS = {"unc": 250.0, "cos": 190.0, "sin": 90.0, "NS": 1116.0, "L": 300.0}
#: EDGES' four loads: cold -> ambient, hot -> hot load, and the 10 m open and shorted cables.
FOUR_LOADS = ("cold", "hot", "c10open", "c10short")
WIDTH = ITPM_CHANNEL_WIDTH_HZ * 8  # 820 channels: the same physics, faster runs
Truth = dict[str, list[float]]
#: Terms of a "smooth" truth (constant included): beyond any order the search reaches.
SMOOTH_TERMS = 12
#: The issue's independent case: each parameter quadratic across the band, its quadratic
#: Legendre coefficient uniform in this range (K, either sign)...
QUADRATIC_K = (1.0, 5.0)
#: ...and its linear one in this (K), the size of the REACH-like truth's T_unc, T_cos, T_sin.
QUADRATIC_LINEAR_K = (5.0, 30.0)
#: A random truth has 1 to this many terms per parameter...
MAX_TERMS = 6
#: ...each higher term log-uniformly this many times the data's own posterior sd.
Z_RANGE = (0.3, 30.0)
#: Random set-ups: this many calibrators (the cold and hot loads always among them, the
#: others REACH's at random; without both the power scale is free, eq. 3.27)...
SETUP_CALIBRATORS = (4, 12)
#: ...each Dicke position integrated log-uniformly this long (s)...
SETUP_INTEGRATION_S = (30.0, 3600.0)
#: ...and in half the runs every reflection with this VNA trace noise.
SETUP_VNA_SIGMA = 1e-3


def _old(data: CalibrationData) -> Solution:
    return solve_radiometric(
        data, prior=RadiometricPrior(coefficients=CoefficientPrior()), average=False
    )


Solver = Callable[[CalibrationData], Solution]
_SHARED = RadiometricPrior(coefficients=ShrinkagePrior(per_parameter=False))

METHODS: dict[str, Solver] = {
    "fixed 3000K": _old,
    "best": lambda data: solve_radiometric(data, average=False),
    "averaged": solve_radiometric,
    "shared scale": lambda data: solve_radiometric(data, prior=_SHARED),
    "shrink 6": lambda data: solve_radiometric(data, OrderChoice.fixed((6,) * 5)),
}


@dataclass(frozen=True)
class Ensemble:
    """A family of runs: the simulator's set-up and how truths are drawn."""

    name: str
    calibrators: tuple[str, ...] = REACH_CALIBRATORS
    integration_s: float = 600.0
    vna_sigma: float = 0.0
    truths: str = "random"  # "reach", "quadratic", "weak", "random" or "smooth"
    channel_width_hz: float = WIDTH
    #: "fixed": every run this set-up; "random": each run its own (:meth:`draw_setup`).
    setups: str = "fixed"

    def draw_setup(self, rng: np.random.Generator) -> Ensemble:
        """One run's set-up: this ensemble's own, or a random one (``setups="random"``).

        A random set-up draws the calibrators (:data:`SETUP_CALIBRATORS`), the integration
        time (:data:`SETUP_INTEGRATION_S`) and whether the VNA is noisy
        (:data:`SETUP_VNA_SIGMA`). A fixed set-up draws nothing, so that its runs do not
        move with this option.
        """
        if self.setups == "fixed":
            return self
        others = [c for c in REACH_CALIBRATORS if c not in ("cold", "hot")]
        n = int(rng.integers(SETUP_CALIBRATORS[0], SETUP_CALIBRATORS[1] + 1))
        picked = set(rng.choice(others, size=n - 2, replace=False).tolist()) | {"cold", "hot"}
        lo, hi = np.log(SETUP_INTEGRATION_S)
        return replace(
            self,
            calibrators=tuple(c for c in REACH_CALIBRATORS if c in picked),
            integration_s=float(np.exp(rng.uniform(lo, hi))),
            vna_sigma=SETUP_VNA_SIGMA if rng.random() < 0.5 else 0.0,
            setups="fixed",
        )

    def config(self, truth: Truth | None) -> SimulationConfig:
        """The simulator's set-up for one truth."""
        return SimulationConfig(
            channel_width_hz=self.channel_width_hz, integration_s=self.integration_s,
            calibrators=self.calibrators, vna_sigma=self.vna_sigma, truth_coefficients=truth,
        )


ENSEMBLES = (
    Ensemble("REACH-like truth, 12 cal, 10 min", truths="reach"),
    Ensemble(
        "quadratics of 1-5 K, 12 cal, 2 min, full resolution", integration_s=120.0,
        truths="quadratic", channel_width_hz=ITPM_CHANNEL_WIDTH_HZ,
    ),
    Ensemble("5 quadratics at 2-6 sigma, 12 cal, 2 min", integration_s=120.0, truths="weak"),
    Ensemble("random truths, 12 cal, 10 min"),
    Ensemble("random truths, 12 cal, 30 s, VNA noise 1e-3", integration_s=30.0, vna_sigma=1e-3),
    Ensemble("random truths, 8 cal, 2 min", REACH_CALIBRATORS[:8], integration_s=120.0),
    Ensemble("random truths, 4 EDGES loads, 1 h", FOUR_LOADS, integration_s=3600.0),
    Ensemble("smooth truths, 12 cal, 10 min", truths="smooth"),
    Ensemble("random truths and set-ups: 4-12 cal, 30 s-1 h, VNA noise or none", setups="random"),
)


def pilot_sd(ensemble: Ensemble, orders: int = MAX_TERMS) -> dict[str, np.ndarray]:
    """Posterior sd of every term at ``orders`` terms (fewer where the data cannot say).

    Under the fixed wide prior, so that the sd is the data's own (what a term's
    detectability means) and the ensemble does not move with the solver's default prior.
    Under the hierarchical prior, at a pilot truth without higher terms, the sd was its
    shrunk width, 10-300 times smaller, and the "0.3-30 sigma" terms mostly undetectable.
    """
    wide = RadiometricPrior(coefficients=CoefficientPrior())
    for n in range(orders, 1, -1):
        truth = {k: [v] + [0.0] * (n - 1) for k, v in LEVELS.items()}
        run = simulate_run(ensemble.config(truth), rng=np.random.default_rng(0))
        try:
            sol = solve_radiometric(
                run.data, OrderChoice.fixed((n,) * 5), prior=wide, average=False
            )
        except IllPosedError:
            continue
        sd = np.sqrt(np.diag(sol.posterior.covariance)).reshape(5, n)
        padded = np.concatenate([sd, np.repeat(sd[:, -1:], orders - n, axis=1)], axis=1)
        return dict(zip(PARAMETERS, padded, strict=True))
    raise IllPosedError(f"{ensemble.name}: not even two terms are constrained")


def draw_truth(
    ensemble: Ensemble, sd: dict[str, np.ndarray], rng: np.random.Generator
) -> Truth | None:
    """A truth of the ensemble's kind (``None``: the simulator's REACH-like default)."""
    if ensemble.truths == "reach":
        return None
    truth: Truth = {}
    for k, level in LEVELS.items():
        if ensemble.truths == "smooth":
            # Every term present, falling geometrically (an analytic function's Legendre
            # coefficients): no order is the true one.
            first = np.exp(rng.uniform(np.log(3.0), np.log(300.0))) * sd[k][1]
            rho = rng.uniform(0.2, 0.6)
            terms = first * rho ** np.arange(SMOOTH_TERMS - 1)
            truth[k] = [level, *(rng.choice([-1.0, 1.0], size=terms.size) * terms)]
            continue
        if ensemble.truths == "quadratic":
            linear, quadratic = rng.uniform(*QUADRATIC_LINEAR_K), rng.uniform(*QUADRATIC_K)
            truth[k] = [level, *(rng.choice([-1.0, 1.0], size=2) * [linear, quadratic])]
            continue
        if ensemble.truths == "weak":
            n, z = 3, np.array([30.0, rng.uniform(2.0, 6.0)])
        else:
            n = int(rng.integers(1, MAX_TERMS + 1))
            lo, hi = np.log(Z_RANGE)
            z = np.exp(rng.uniform(lo, hi, size=n - 1))
        signs = rng.choice([-1.0, 1.0], size=n - 1)
        truth[k] = [level, *(signs * z * sd[k][1:n])]
    return truth


@dataclass
class Tally:
    """What one method did over an ensemble's runs."""

    ratios: list[float] = field(default_factory=list)
    honesty: list[float] = field(default_factory=list)
    hits: list[list[float]] = field(default_factory=list)
    failures: int = 0
    #: For each solved run: its place among the ensemble's runs (to pair methods run by
    #: run), and how many terms the chosen model holds beyond the truth's orders and
    #: falls short of them (each summed over the five parameters).
    runs: list[int] = field(default_factory=list)
    beyond: list[int] = field(default_factory=list)
    short: list[int] = field(default_factory=list)

    def misses(self) -> list[str]:
        """The issue's bounds this tally misses (empty: every one met)."""
        if not self.ratios:
            return ["no run solved"]
        r, h, c = np.array(self.ratios), np.array(self.honesty), np.mean(self.hits, axis=0)
        checks = {
            "median <= 1.05": np.median(r) <= 1.05,
            "RMS <= 1.10": np.sqrt(np.mean(r**2)) <= 1.10,
            "act/pred 0.9-1.1": 0.9 <= np.sqrt(np.mean(h**2)) <= 1.1,
            "68 +- 3 %": abs(100 * c[0] - 68) <= 3,
            "95 +- 2 %": abs(100 * c[1] - 95) <= 2,
        }
        return [name for name, ok in checks.items() if not ok]

    def rms_sd(self, draws: int = 2000) -> float:
        """Bootstrap sd of the RMS over runs: how far the runs' own noise moves it."""
        r = np.array(self.ratios)
        rng = np.random.default_rng(0)
        picks = rng.integers(0, r.size, size=(draws, r.size))
        return float(np.std(np.sqrt(np.mean(r[picks] ** 2, axis=1))))

    def line(self) -> str:
        """One row of the table."""
        if not self.ratios:
            return f"no run solved ({self.failures} failed)"
        r, h, c = np.array(self.ratios), np.array(self.honesty), np.mean(self.hits, axis=0)
        failed = f"  ({self.failures} failed)" if self.failures else ""
        return (
            f"{np.median(r):6.3f} {np.sqrt(np.mean(r**2)):6.3f} {np.sqrt(np.mean(h**2)):8.3f}"
            f"   {100 * c[0]:4.0f} % {100 * c[1]:4.0f} %{failed}"
        )


def excess_split(chosen: Tally, truth: Tally) -> str:
    """Where ``chosen``'s error exceeds the true orders', run by run: which way it chose.

    The excess of a run is ``(error / floor)^2`` of ``chosen`` less that of ``truth`` on
    the same run (runs either failed are left out). Its mean is split over three kinds of
    run: those whose chosen model holds terms beyond the truth's orders (noise fitted, or
    structure moved between parameters), those only short of them (structure dropped: the
    issue's case), and those at the truth's orders. Each kind's mean excess a run and
    share of the whole are given, the whole with its standard error.
    """
    oracle = dict(zip(truth.runs, truth.ratios, strict=True))
    paired = [
        (ratio**2 - oracle[i] ** 2, more > 0, fewer > 0)
        for i, ratio, more, fewer in zip(
            chosen.runs, chosen.ratios, chosen.beyond, chosen.short, strict=True
        )
        if i in oracle
    ]
    if not paired:
        return "no run both solved"
    excess, beyond, short = (np.array(column) for column in zip(*paired, strict=True))
    short &= ~beyond
    total = float(np.sum(excess))
    parts = []
    for label, kind in (
        ("runs with terms beyond the truth's orders", beyond),
        ("only short of them", short),
        ("at them", ~beyond & ~short),
    ):
        if kind.any():
            share = f" ({100 * np.sum(excess[kind]) / total:.0f} %)" if total > 0 else ""
            parts.append(f"{kind.sum()} {label}: {np.mean(excess[kind]):.3f}{share}")
    sem = np.std(excess) / np.sqrt(excess.size)
    return f"{np.mean(excess):.3f} +- {sem:.3f} a run; " + ", ".join(parts)


def own_prior(sd: dict[str, np.ndarray]) -> Solver:
    """The random truths' own prior (module docstring): the oracle ``own prior``.

    A size ``z sd`` with ``log z`` uniform on :data:`Z_RANGE` has the mean square
    ``sd^2 (hi^2 - lo^2) / (2 log(hi / lo))``; the Gaussian of that variance stands for it.
    """
    lo, hi = Z_RANGE
    z_rms = np.sqrt((hi**2 - lo**2) / (2.0 * np.log(hi / lo)))
    prior = TermPrior(term_sd_k={k: list(z_rms * v[1:MAX_TERMS]) for k, v in sd.items()})
    box = OrderChoice(max_orders=(MAX_TERMS,) * 5, ceiling=MAX_TERMS)
    return partial(solve_radiometric, orders=box, prior=RadiometricPrior(coefficients=prior))


def run_ensemble(
    ensemble: Ensemble, runs: int, seed: int = 0, wanted: set[str] | None = None
) -> dict[str, Tally]:
    """Every method (or the default and those ``wanted``) on ``runs`` seeded runs.

    A run is left out where its truth has no noise floor, or, with random set-ups, where
    the drawn set-up solves no fixed orders of two terms or more (:func:`pilot_sd`).
    """
    fixed_sd = pilot_sd(ensemble) if ensemble.setups == "fixed" else None
    methods = dict(METHODS)
    if wanted:
        methods = {k: v for k, v in methods.items() if k in wanted | {"averaged"}}
    oracle_prior = ensemble.truths == "random" and (not wanted or "own prior" in wanted)
    tallies = {name: Tally() for name in [*methods, *(["own prior"] * oracle_prior), "true orders"]}
    rng = np.random.default_rng(seed)
    for index in range(runs):
        setup = ensemble.draw_setup(rng)
        try:
            sd = fixed_sd if fixed_sd is not None else pilot_sd(setup)
        except IllPosedError:  # a drawn set-up no fixed orders solve: nothing to choose
            continue
        truth = draw_truth(setup, sd, rng)
        run = simulate_run(setup.config(truth), rng=rng)
        data, source = run.data, run.validation_noiseless
        try:
            floor = noise_floor(data, source, run.truth.parameters).rms
        except (IllPosedError, np.linalg.LinAlgError):
            continue
        channels = np.linspace(0, data.freq_hz.size - 1, 8).astype(int)
        oracle = partial(
            solve_radiometric, orders=OrderChoice.fixed(run.truth.parameters.orders),
            prior=RadiometricPrior(coefficients=CoefficientPrior()),
        )
        solvers: dict[str, Solver] = {**methods, "true orders": oracle}
        if oracle_prior:  # it knows the drawn sizes' sd, the set-up's own
            solvers["own prior"] = own_prior(sd)
        for name, solver in solvers.items():
            try:
                solution = solver(data)
                calibrated = solution.calibrate(
                    data.freq_hz, data.gamma_rec, source, gamma_rec_std=data.gamma_rec_std
                )
            except IllPosedError:
                tallies[name].failures += 1
                continue
            error = calibrated.mean - run.validation_temperature_k
            actual = float(np.sqrt(np.mean(error**2)))
            # The validation source's Q is noiseless (no channel width given, so no
            # radiometer term): its predictive is the calibration's error plus, with VNA
            # noise, the receiver reflection's (a per-channel error of its own).
            predicted = float(np.sqrt(np.mean(calibrated.std**2)))
            truth_k = run.validation_temperature_k
            tallies[name].ratios.append(actual / floor)
            tallies[name].honesty.append(actual / predicted)
            tallies[name].hits.append([
                float(np.mean(calibrated.covers(truth_k, level)[channels]))
                for level in (0.68, 0.95)
            ])
            step = np.subtract(solution.best_orders, run.truth.parameters.orders)
            tallies[name].runs.append(index)
            tallies[name].beyond.append(int(np.sum(np.maximum(step, 0))))
            tallies[name].short.append(int(np.sum(np.maximum(-step, 0))))
    return tallies


def main(argv: list[str] | None = None) -> dict[str, dict[str, Tally]]:
    """Run every ensemble; print one table per ensemble."""
    args = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    args.add_argument("--runs", type=int, default=30, help="runs per ensemble (30)")
    args.add_argument(
        "--seed", type=int, default=0,
        help="seed of every ensemble's truths and noise (0); the solvers are deterministic, "
        "so a method's row does not depend on which others run",
    )
    args.add_argument(
        "--only", default="",
        help="run only the ensembles whose name contains this text (say '8 cal')",
    )
    args.add_argument(
        "--methods", default="",
        help="comma-separated methods to run beside 'averaged' and 'true orders' (all)",
    )
    options = args.parse_args(argv)
    chosen = [e for e in ENSEMBLES if options.only in e.name]
    if not chosen:
        args.error(f"--only {options.only!r} names no ensemble")
    wanted = {m.strip() for m in options.methods.split(",") if m.strip()}
    known = {*METHODS, "own prior", "true orders"}
    if wanted - known:
        args.error(f"--methods: unknown {sorted(wanted - known)}; known: {sorted(known)}")
    results = {}
    for ensemble in chosen:
        tallies = run_ensemble(ensemble, options.runs, options.seed, wanted)
        results[ensemble.name] = tallies
        channels = ensemble.config(None).frequencies().size
        print(f"\n{ensemble.name} ({options.runs} runs, {channels} channels)")
        print(f"  {'method':<12} median    RMS  act/pred   68 %   95 %   (error / floor)")
        for name, tally in tallies.items():
            print(f"  {name:<12} {tally.line()}")
        default = tallies["averaged"]
        missed = default.misses()
        verdict = "misses " + ", ".join(missed) if missed else "all met"
        print(f"  the default (averaged) against the issue's bounds: {verdict}")
        if default.ratios:
            print(f"  (the RMS over runs has a bootstrap sd of {default.rms_sd():.3f})")
            print(
                "  the default's (error / floor)^2 less the true orders', by the orders it chose: "
                + excess_split(default, tallies["true orders"])
            )
    return results


if __name__ == "__main__":
    main()
