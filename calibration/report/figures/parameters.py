"""Figures of a solution alone: the noise-wave parameters with their bands, the evidence.

* :func:`noise_wave_parameters` (thesis figs. 4.7, 4.20): each parameter's posterior mean
  against frequency, and beside it its departure from that mean with the 68 % and 95 %
  credible bands (the bands are a few mK to K on parameters of hundreds of K, invisible on
  the left). A model-averaged posterior (:class:`~calibration.choice.averaging.MixturePosterior`)
  gives its bands as quantiles of draws from the mixture (solution files keep its
  components); a single model as Student-t quantiles of
  :meth:`~calibration.solve.solution.Solution.parameter_std`. A per-channel solution
  (:class:`~calibration.solve.per_frequency.ChannelSolution`) is drawn on its own channels with
  Gaussian bands of its per-channel std (undefined errors: no band).
* :func:`evidence_landscape` (thesis fig. 4.5): the evidence profile over each
  parameter's order, and the leading models with their weights.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from numpy.typing import NDArray
from scipy import stats

from ...choice.averaging import MixturePosterior
from ...model.data import CalibrationData
from ...model.noise_waves import PARAMETERS, design_terms
from ...model.polynomial_model import PolynomialParameters
from ...solve.per_frequency import ChannelSolution
from ...solve.solution import Solution
from ...solve.solvers import AnySolution, method_name
from ..model_used import leading_models, model_used_line, orders_text, orders_used_weight
from .style import (
    BAND_ALPHA,
    LEGEND_ROW_IN,
    PARAMETER_COLOURS,
    PARAMETER_LABELS,
    Space,
    grid,
    legend_below,
    mhz,
    new_figure,
    note,
    styled,
    suptitle,
)

FloatArray = NDArray[np.float64]

#: Credible levels of the bands.
LEVELS = (0.68, 0.95)
#: Draws from a mixture posterior for its quantiles: at 1000 the band's edges are smooth
#: to a pixel or two (2000 cost twice the time and looked the same).
MIXTURE_DRAWS = 1000
#: Models listed in the evidence figure.
TOP_MODELS = 12
#: Delta log Z is linear within this many nats of the best, logarithmic beyond.
LINEAR_NATS = 10.0
#: A calibrator is reflective at a median ``|Gamma|`` of at least this.
REFLECTIVE = 0.3
#: Reflective calibrators share a phase (to within pi) when the median
#: ``|sin(alpha_i - alpha_0)|`` is below this.
ALIGNED = 0.2


def parameter_bands(
    solution: AnySolution, freq_hz: FloatArray, seed: int = 0
) -> tuple[FloatArray, dict[float, tuple[FloatArray, FloatArray]]]:
    """Posterior mean ``(5, n)`` and, per level, the band's (low, high) about that mean."""
    mean = solution.evaluate(freq_hz)
    bands: dict[float, tuple[FloatArray, FloatArray]] = {}
    if isinstance(solution, Solution) and isinstance(solution.posterior, MixturePosterior):
        draws = solution.sample_parameters(freq_hz, MIXTURE_DRAWS, np.random.default_rng(seed))
        probabilities = [0.5 + sign * level / 2 for level in LEVELS for sign in (-1, 1)]
        quantiles = np.quantile(draws, probabilities, axis=0) - mean
        for i, level in enumerate(LEVELS):
            bands[level] = (quantiles[2 * i], quantiles[2 * i + 1])
        return mean, bands
    std = solution.parameter_std(freq_hz)
    std = np.where(np.isfinite(std), std, np.nan)  # undefined errors: no band
    dof = solution.posterior.dof if isinstance(solution, Solution) else solution.dof
    for level in LEVELS:
        q = 0.5 + level / 2
        z = float(stats.norm.ppf(q) if np.isinf(dof) else stats.t.ppf(q, dof))
        bands[level] = (-z * std, z * std)
    return mean, bands


@styled
def noise_wave_parameters(
    solution: AnySolution,
    freq_hz: FloatArray | None = None,
    truth: PolynomialParameters | None = None,
    n_channels: int = 200,
    data: CalibrationData | None = None,
) -> Figure:
    """The five noise-wave parameters (K) against frequency, with 68/95 % bands.

    ``freq_hz`` defaults to ``n_channels`` points over the solution's band (a per-channel
    solution's own channels); ``truth`` (a simulated receiver's parameters) is drawn on
    both columns when given. With the run's ``data``, the frequencies where the
    reflective calibrators measure ``T_cos`` or ``T_sin`` alone are ticked and explained
    (:func:`single_phase_frequencies`: why those bands pinch).
    """
    if freq_hz is not None:
        freq = np.asarray(freq_hz, dtype=float)
    elif isinstance(solution, ChannelSolution):
        freq = solution.freq_hz
    else:
        freq = np.linspace(solution.basis.f_lo_hz, solution.basis.f_hi_hz, n_channels)
    mean, bands = parameter_bands(solution, freq)
    true = None if truth is None else truth.evaluate(freq)
    fig = new_figure(8.6 + (0.35 if data is not None else 0.0))
    bottom = 0.6 + LEGEND_ROW_IN + (0.35 if data is not None else 0.0)
    spec = grid(fig, len(PARAMETERS), 2, Space(bottom=bottom, hspace=0.18))
    axes = spec.subplots(sharex=True, squeeze=False)
    x = mhz(freq)
    for k, name in enumerate(PARAMETERS):
        colour, label = PARAMETER_COLOURS[name], PARAMETER_LABELS[name]
        left, right = axes[k]
        left.plot(x, mean[k], color=colour, label="posterior mean")
        left.set_ylabel(f"{label} (K)")
        for level, alpha in zip(LEVELS, BAND_ALPHA, strict=True):
            lo, hi = bands[level]
            right.fill_between(
                x, lo[k], hi[k], color=colour, alpha=alpha, lw=0, label=f"{level:.0%} band"
            )
        right.axhline(0.0, color=colour, lw=0.8)
        right.set_ylabel(f"{label} − mean (K)")
        if true is not None:
            left.plot(x, true[k], color="k", ls="--", lw=0.9, label="truth")
            right.plot(x, true[k] - mean[k], color="k", ls="--", lw=0.9, label="truth − mean")
    axes[0, 0].set_title("posterior mean")
    axes[0, 1].set_title("departure from the mean: 68 % and 95 % credible bands")
    for ax in axes[-1]:
        ax.set_xlabel("frequency (MHz)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    more, more_labels = axes[0, 1].get_legend_handles_labels()
    legend_below(fig, handles + more, labels + more_labels, columns=5)
    if isinstance(solution, ChannelSolution):
        how = f"{method_name(solution)} solver, per channel"
    else:
        how = f"{solution.method} solver, {model_used_title(solution)}"
    suptitle(fig, f"Noise-wave parameters ({how})")
    if data is not None and not isinstance(solution, ChannelSolution):
        _mark_single_phase(fig, axes, data, freq)
    return fig


def model_used_title(solution: Solution) -> str:
    """The model used, short: ``orders 16,12,12,8,8, weight 0.997 of the average``."""
    used = orders_text(solution.orders_used)
    if getattr(solution.basis, "delays_s", ()):
        return f"orders {model_used_line(solution).split(' (')[0]}: polynomials + delay terms"
    if solution.metadata.get("averaged") and len(solution.evidence_table) > 1:
        return f"orders {used}, weight {orders_used_weight(solution):.3f} of the average"
    return f"orders {used}"


def single_phase_frequencies(data: CalibrationData) -> dict[str, FloatArray] | None:
    """Where the reflective calibrators measure ``T_cos`` (or ``T_sin``) alone (Hz).

    The design terms of ``T_cos`` and ``T_sin`` (eq. 3.25-3.26) are
    ``X_cos, X_sin ~ |Gamma F| cos(alpha), sin(alpha)`` with ``alpha`` the phase of
    ``Gamma_src F``. A calibrator measures one combination of the two,
    ``cos(alpha) T_cos + sin(alpha) T_sin``. When the reflective calibrators share a phase
    to within pi (an open and a short at the end of one cable, EDGES' four loads), every
    one measures the same combination at each frequency, and it rotates with the cable's
    delay: ``T_cos`` alone where ``X_sin = 0``, ``T_sin`` alone where ``X_cos = 0``. There
    their credible bands pinch to the radiometer noise; between, the other combination is
    held only by the polynomials' smoothness. Returns those zero crossings of the most
    reflective calibrator by parameter (``"cos"``: where ``X_sin = 0``), or None when the
    reflective calibrators' phases differ (no pinch: REACH's twelve) or there are none.
    """
    reflective = [
        s for s in data.sources.values() if np.median(np.abs(s.gamma)) >= REFLECTIVE
    ]
    if not reflective:
        return None
    phases = []
    for src in reflective:
        terms = design_terms(src.gamma, data.gamma_rec)
        phases.append(np.angle(terms.x_cos + 1j * terms.x_sin))
    if any(np.median(np.abs(np.sin(p - phases[0]))) > ALIGNED for p in phases[1:]):
        return None
    lead = max(reflective, key=lambda s: float(np.median(np.abs(s.gamma))))
    terms = design_terms(lead.gamma, data.gamma_rec)
    out = {}
    for name, term in (("cos", terms.x_sin), ("sin", terms.x_cos)):
        crossing = np.flatnonzero(np.diff(np.sign(term)) != 0)
        out[name] = data.freq_hz[crossing]
    return out


def _mark_single_phase(fig: Figure, axes: Any, data: CalibrationData, freq: FloatArray) -> None:
    """Tick where the reflective loads measure T_cos / T_sin alone, and say why below."""
    marks = single_phase_frequencies(data)
    if not marks:
        return
    for k, name in ((1, "cos"), (2, "sin")):
        ax = axes[k, 1]
        inside = marks[name][(marks[name] >= freq[0]) & (marks[name] <= freq[-1])]
        ax.plot(mhz(inside), np.zeros(inside.size), "|", color="k", ms=9, mew=1.0)
    fig.text(
        0.5, (LEGEND_ROW_IN + 0.02) / fig.get_size_inches()[1],
        "| : the reflective calibrators share one phase (to within π), so each frequency "
        "measures one combination cos α T_cos + sin α T_sin, rotating with the cable's "
        "delay;\nT_cos is measured alone where X_sin = 0 and T_sin where X_cos = 0: with "
        "terms enough to follow the rotation the bands pinch there, and between them "
        "smoothness alone holds the other combination",
        ha="center", va="bottom", fontsize=8, color="0.3",
    )


def evidence_profile(solution: Solution) -> dict[str, dict[int, float]]:
    """Per parameter, the best log Z over models with each number of terms, minus the best."""
    table = solution.evidence_table
    if not table:
        return {}
    best = max(table.values())
    profile: dict[str, dict[int, float]] = {name: {} for name in PARAMETERS}
    for orders, logz in table.items():
        for name, n in zip(PARAMETERS, orders, strict=True):
            row = profile[name]
            row[n] = max(row.get(n, -np.inf), logz - best)
    return profile


_SUPERSCRIPTS = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def _power_of_ten(value: float, _position: int | None = None) -> str:
    """A symlog tick label: ``0``, ``−10``, ``−10³`` (Unicode: mathtext costs a parse each)."""
    if value == 0:
        return "0"
    exponent = round(np.log10(abs(value)))
    sign = "−" if value < 0 else ""
    if not np.isclose(abs(value), 10.0**exponent):
        return f"{value:g}".replace("-", "−")
    return sign + ("10" if exponent == 1 else f"10{str(exponent).translate(_SUPERSCRIPTS)}")


@styled
def evidence_landscape(solution: Solution) -> Figure:
    """The evidence over model orders: a profile per parameter and the leading models."""
    fig = new_figure(4.8)
    space = Space(top=0.35, bottom=0.6 + LEGEND_ROW_IN, left=0.9, wspace=1.35)
    spec = grid(fig, 1, 2, space, width_ratios=(1.1, 1))
    prof_ax, top_ax = fig.add_subplot(spec[0, 0]), fig.add_subplot(spec[0, 1])
    table = solution.evidence_table
    if not table:
        note(prof_ax, "this solution has no evidence table\n(its orders were fixed)")
        top_ax.remove()
        return fig
    used = solution.orders_used
    for k, (name, row) in enumerate(evidence_profile(solution).items()):
        ns = sorted(row)
        values = [row[n] for n in ns]
        offset = (k - 2) * 0.06
        prof_ax.plot(
            np.add(ns, offset), values, "o-", color=PARAMETER_COLOURS[name], ms=4,
            label=PARAMETER_LABELS[name],
        )
        if k < len(used) and used[k] in row:
            prof_ax.plot(used[k] + offset, row[used[k]], "*", color=PARAMETER_COLOURS[name],
                         ms=12)
    prof_ax.set_xlabel("number of polynomial terms of the parameter")
    prof_ax.set_ylabel("best Δ log Z over the other orders (nats)")
    prof_ax.text(0.01, 0.01, f"linear within {LINEAR_NATS:g} nats, logarithmic below",
                 transform=prof_ax.transAxes, fontsize=8, color="0.4")
    delays = bool(getattr(solution.basis, "delays_s", ()))
    prof_ax.set_title(
        f"polynomial search ({len(table)} models); the model used adds delay terms" if delays
        else f"evidence profile ({len(table)} models; ★ the model used)"
    )
    prof_ax.set_yscale("symlog", linthresh=LINEAR_NATS)
    prof_ax.yaxis.set_major_formatter(FuncFormatter(_power_of_ten))
    prof_ax.set_ylim(top=3)
    handles, labels = prof_ax.get_legend_handles_labels()
    legend_below(fig, handles, labels, columns=5)

    ranked = ranked_models(solution)
    top = max(table.values())
    labels = [",".join(map(str, o)) for o, _, _ in ranked]
    deltas = [table[o] - top if o in table else np.nan for o, _, _ in ranked]
    y = np.arange(len(ranked))
    top_ax.barh(y, np.nan_to_num(deltas), color="C0", alpha=0.7)
    top_ax.set_yticks(y, labels, fontfamily="monospace")
    top_ax.invert_yaxis()
    top_ax.set_xlabel("Δ log Z from the evidence-best (nats)")
    finite = [d for d in deltas if np.isfinite(d)]
    span = min(finite) if finite and min(finite) < 0 else -1.0
    top_ax.set_ylabel("orders (unc, cos, sin, NS, L)")
    averaged = any(w is not None for _, w, _ in ranked)
    top_ax.set_title(
        "models by weight in the average (then by evidence)" if averaged
        else "polynomial models by evidence, before the delay terms" if delays
        else "leading models by evidence"
    )
    for yi, (_, weight, _) in zip(y, ranked, strict=True):
        if averaged:
            text = f"{weight:.3f}" if weight is not None else "—"
            top_ax.text(span * 1.02, float(yi), text, va="center", ha="right", fontsize=9)
    for yi, (orders, _, _) in zip(y, ranked, strict=True):
        if orders == used:
            top_ax.get_yticklabels()[int(yi)].set_fontweight("bold")
    top_ax.set_xlim(span * (1.3 if averaged else 1.05), 0.05 * abs(span))
    return fig


def ranked_models(solution: Solution, limit: int = TOP_MODELS) -> list[tuple[Any, Any, Any]]:
    """The evidence panel's rows: ``(orders, weight or None, log Z or None)``.

    The models that carry the average's weight first, heaviest first (those the solution
    records, ``metadata["model_weights"]``), then the evidence table's best by log Z to
    ``limit`` rows. A model's weight is its posterior probability with the hypotheses'
    priors (:mod:`calibration.choice.averaging`), so the heaviest need not be the evidence-best.
    """
    table = solution.evidence_table
    rows: list[tuple[Any, Any, Any]] = []
    seen = set()
    if solution.metadata.get("averaged"):
        for orders, weight in leading_models(solution, limit):
            rows.append((orders, weight, table.get(orders)))  # type: ignore[arg-type]
            seen.add(orders)
    for orders, logz in sorted(table.items(), key=lambda item: -item[1]):
        if len(rows) >= limit:
            break
        if tuple(orders) not in seen:
            rows.append((tuple(orders), None, logz))
    return rows
