"""RFI flags on simulated sky spectra: ours against EDGES' xrfi on the same spectra.

Every spectrum is a power-law sky ``5000 K (f / 50 MHz)^beta``, ``beta`` in -2.8..-2.2,
over a band of 4096 channels from ``lo`` in 40-80 MHz to ``hi`` in ``lo + 50``..200
MHz, with radiometer noise ``T / sqrt(B tau)`` for ``tau`` log-uniform in 1 s..1 h; half
of them carry a 21-cm-like trough (0.5 K deep, 20 MHz wide at 78 MHz). Then, per kind:

* **clean**: nothing added; the false-flag rate per channel, and the spectra with a
  trough where any channel within 68-88 MHz is flagged (must be none);
* **spikes**: 20 spikes of 1-3 channels at ``a`` sigma of the radiometer noise; recall =
  the fraction of spikes whose channels are all flagged;
* **humps**: one Gaussian hump of FWHM ``w`` MHz and ``a`` sigma per channel at its peak;
  recall = the fraction of humps with at least half the channels within their FWHM
  flagged; "spill" = flagged channels per spectrum where the hump adds under 0.1 sigma;
* **bursts in time**: nights of 24 spectra of 200 s (50-130 MHz, the sky's level and
  index changing with LST by 20 % and 0.05); one spectrum gets a burst over the whole
  band of ``a`` sigma per channel, or a 2 MHz hump of ``a`` sigma; recall = that spectrum
  flagged whole (band burst) or the hump found as above, by each flagger one spectrum at a
  time and by ours with the night's flags
  (:func:`calibration.checks.rfi_night.flag_night`).

Ours is :func:`calibration.checks.rfi.flag_sky` (5 sigma, with the channels'
frequencies: narrow spikes, then broad humps up to 4 MHz). xrfi is edges-analysis 8.3.0's
``edges.filters.xrfi`` (see :mod:`benchmarks.xrfi_worker` for the exact calls):

* ``xrfi_iterative`` with its documented defaults: a 37-term Fourier model of the
  data, a 15-term Fourier model of its standard deviation, 5 sigma, at most 20
  iterations, the whole spectrum flagged if it does not converge (``rfi_iterative_filter``
  in edges-analysis' own pipeline calls this function, with frequencies in MHz). The
  Fourier basis' default period is 2 pi in those units, so on a power-law sky the model
  leaves residuals of ~1000 K and nothing is flagged: the column shows the defaults, not
  what the function can do;
* ``xrfi_iterative`` with a sky's model (our choice, not EDGES'): a 5-term ``LinLog``
  foreground and the standard deviation from a running median of 31 channels
  (``MedianFilterModeler``), 5 sigma;
* ``xrfi_iterative_sliding_window``, "algorithmically the same as that used in
  Bowman+2018" (its docstring), with its defaults (2.5 sigma, positive outliers only,
  RMS in windows of 1/16 of the band) and a 5-term ``LinLog`` foreground model. EDGES'
  configuration files for sky data are not in the package: these are the settings its
  docstring and the paper name, not a pipeline's.

edges-analysis joins the ``bench`` extra (``pip install -e '.[bench]'``; it resolves beside
``edges-cal==7.1.1``), and is then called in this process. Where it is not installed
here, ``--xrfi-python PATH`` (or the environment variable ``REACH_XRFI_PYTHON``) names an
interpreter that has it, which runs :mod:`benchmarks.xrfi_worker` in a subprocess on the
same spectra; without either, the xrfi columns are left out::

    python -m benchmarks.rfi [--spectra 10] [--seed 0] [--xrfi-python /tmp/venv-ea/bin/python]

The measured table is in ``benchmarks/README.md``; its summary in docs/astronomers-guide.md.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.checks.rfi import flag_sky
from calibration.checks.rfi_night import flag_night

N_CHANNELS = 4096
SPIKE_SIGMAS = (5.0, 8.0, 15.0, 30.0, 100.0)
HUMP_WIDTHS_MHZ = (2.0, 5.0, 10.0)
HUMP_SIGMAS = (0.5, 1.0, 2.0, 5.0, 10.0, 50.0)
BURST_SIGMAS = (0.5, 1.0, 2.0, 5.0)
NIGHT_SPECTRA = 24
NIGHT_SECONDS = 200.0
FLAGGERS = ("ours", "xrfi_iterative_default", "xrfi_iterative_linlog", "xrfi_sliding_window_b18")


@dataclass
class Case:
    """One spectrum, what was put in it, and how to score a flagger's flags of it."""

    kind: str
    key: tuple[float, ...]
    freq_mhz: np.ndarray
    spectrum: np.ndarray
    sigma: float
    truth: np.ndarray  # channels holding the injected signal (clean: none)
    groups: list[np.ndarray] = field(default_factory=list)  # spikes / the hump's core
    added: np.ndarray | None = None  # added signal in sigma per channel
    trough: bool = False
    flags: dict[str, np.ndarray] = field(default_factory=dict)


def sky(
    rng: np.random.Generator, seconds: float | None = None
) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """A clean sky of the family (module docstring): frequencies, T, sigma, trough."""
    lo = rng.uniform(40.0, 80.0)
    hi = rng.uniform(lo + 50.0, 200.0)
    f = np.linspace(lo, hi, N_CHANNELS)
    t = 5000.0 * (f / 50.0) ** rng.uniform(-2.8, -2.2)
    trough = bool(rng.random() < 0.5)
    if trough:
        t = t - 0.5 * np.exp(-0.5 * ((f - 78.0) / 8.5) ** 2)
    tau = 10 ** rng.uniform(0.0, np.log10(3600.0)) if seconds is None else seconds
    sigma = float(1 / np.sqrt((f[1] - f[0]) * 1e6 * tau))
    return f, t * (1 + sigma * rng.standard_normal(f.size)), sigma, trough


def clean_cases(rng: np.random.Generator, n: int) -> list[Case]:
    out = []
    for _ in range(n):
        f, x, sigma, trough = sky(rng)
        out.append(Case("clean", (), f, x, sigma, np.zeros(f.size, bool), trough=trough))
    return out


def spike_cases(rng: np.random.Generator, n: int) -> list[Case]:
    out = []
    for a in SPIKE_SIGMAS:
        for _ in range(n):
            f, x, sigma, trough = sky(rng)
            starts = np.sort(rng.choice(np.arange(20, f.size - 20, 8), 20, replace=False))
            truth = np.zeros(f.size, bool)
            groups = []
            for s in starts:
                where = np.arange(s, s + int(rng.integers(1, 4)))
                x[where] *= 1 + a * sigma
                truth[where] = True
                groups.append(where)
            out.append(Case("spikes", (a,), f, x, sigma, truth, groups, trough=trough))
    return out


def add_hump(
    rng: np.random.Generator, f: np.ndarray, x: np.ndarray, sigma: float, width: float, a: float
) -> tuple[np.ndarray, np.ndarray]:
    """Multiply in a hump; its core (channels within its FWHM) and added sigma per channel."""
    centre = rng.uniform(f[0] + width, f[-1] - width)
    profile = a * np.exp(-4 * np.log(2) * ((f - centre) / width) ** 2)
    x *= 1 + sigma * profile
    return np.flatnonzero(np.abs(f - centre) <= width / 2), profile


def hump_cases(rng: np.random.Generator, n: int) -> list[Case]:
    out = []
    for width in HUMP_WIDTHS_MHZ:
        for a in HUMP_SIGMAS:
            for _ in range(n):
                f, x, sigma, trough = sky(rng)
                core, added = add_hump(rng, f, x, sigma, width, a)
                out.append(Case("humps", (width, a), f, x, sigma, added > 0.1, [core], added,
                                trough))
    return out


def night_cases(rng: np.random.Generator, n: int) -> tuple[list[Case], list[Case]]:
    """Per night: the spectrum with the burst (scored), and all of the night's spectra."""
    scored, nights = [], []
    f = np.linspace(50.0, 130.0, N_CHANNELS)
    sigma = float(1 / np.sqrt((f[1] - f[0]) * 1e6 * NIGHT_SECONDS))
    lst = np.linspace(0.0, 1.0, NIGHT_SPECTRA)[:, None]
    for kind in ("band burst", "hump in time"):
        for a in BURST_SIGMAS:
            for _ in range(n):
                phase = rng.uniform(0, 2 * np.pi)
                t = 5000 * (1 + 0.2 * np.sin(3 * lst + phase)) * (f / 50) ** (-2.5 - 0.05 * lst)
                x = t * (1 + sigma * rng.standard_normal(t.shape))
                row = int(rng.integers(1, NIGHT_SPECTRA - 1))
                if kind == "band burst":
                    x[row] *= 1 + a * sigma
                    case = Case(kind, (a,), f, x[row], sigma, np.ones(f.size, bool))
                else:
                    spectrum = x[row].copy()
                    core, added = add_hump(rng, f, spectrum, sigma, 2.0, a)
                    x[row] = spectrum
                    case = Case(kind, (a,), f, spectrum, sigma, added > 0.1, [core], added)
                case.flags["night_rows"] = np.array([row])
                scored.append(case)
                nights.append(Case("night", (a,), f, x, sigma, np.zeros(0, bool)))
    return scored, nights


def run_xrfi(cases: list[Case], python: str | None) -> bool:
    """The xrfi flags of every case, in this process or through ``python`` (module doc)."""
    spectra = np.stack([c.spectrum for c in cases])
    freqs = np.stack([c.freq_mhz for c in cases])
    try:
        from benchmarks.xrfi_worker import run

        out = run(spectra, freqs)
    except ImportError:
        if not python:
            print("edges-analysis not importable and no --xrfi-python: xrfi left out")
            return False
        worker = Path(__file__).with_name("xrfi_worker.py")
        with tempfile.TemporaryDirectory() as tmp:
            source, target = Path(tmp, "in.npz"), Path(tmp, "out.npz")
            np.savez(source, spectra=spectra, freqs_mhz=freqs)
            subprocess.run([python, str(worker), str(source), str(target)], check=True)
            with np.load(target) as data:
                out = {k: data[k] for k in data.files}
    for name, flags in out.items():
        for case, row in zip(cases, flags, strict=True):
            case.flags[f"xrfi_{name}"] = row
    return True


def found(case: Case, flags: np.ndarray) -> list[bool]:
    """Per injected group: spikes all flagged; a hump's core at least half flagged."""
    if case.kind == "spikes":
        return [bool(np.all(flags[g])) for g in case.groups]
    if case.kind == "band burst":
        return [bool(np.mean(flags) > 0.5)]
    return [bool(np.mean(flags[g]) >= 0.5) for g in case.groups]


def table(cases: list[Case], nights_scored: list[Case], flaggers: list[str]) -> None:
    """Print false flags, recall and spill per kind and amplitude."""
    head = " ".join(f"{name:>24}" for name in flaggers)
    clean = [c for c in cases if c.kind == "clean"]
    print(f"\nclean skies ({len(clean)}, {N_CHANNELS} channels each): false flags per channel;"
          " trough spectra flagged within 68-88 MHz")
    print(f"{'':24}{head}")
    rates = [np.mean([c.flags[n].mean() for c in clean]) for n in flaggers]
    print(f"{'false-flag rate':24}" + " ".join(f"{r:24.2e}" for r in rates))
    with_trough = [c for c in clean if c.trough]
    hits = [sum(bool(np.any(c.flags[n][(c.freq_mhz > 68) & (c.freq_mhz < 88)]))
                for c in with_trough) for n in flaggers]
    print(f"{'trough flagged':24}" + " ".join(f"{f'{h}/{len(with_trough)}':>24}" for h in hits))
    for kind, label in (("spikes", "a (sigma)"), ("humps", "w (MHz), a (sigma)")):
        group = [c for c in cases if c.kind == kind]
        print(f"\n{kind}: recall (spill: flags per spectrum where under 0.1 sigma was added)")
        print(f"{label:24}{head}")
        for key in sorted({c.key for c in group}):
            same = [c for c in group if c.key == key]
            cells = []
            for n in flaggers:
                recall = np.mean([x for c in same for x in found(c, c.flags[n])])
                spill = np.mean([np.count_nonzero(c.flags[n] & ~c.truth) for c in same])
                cells.append(f"{recall:.2f} ({spill:.0f})")
            print(f"{', '.join(f'{k:g}' for k in key):24}" + " ".join(f"{x:>24}" for x in cells))
    names = [*flaggers, "ours + night"]
    print("\nbursts in time (nights of 24 x 200 s): recall; a band burst: its spectrum flagged")
    print(f"{'kind, a (sigma)':24}" + " ".join(f"{n:>24}" for n in names))
    for kind in ("band burst", "hump in time"):
        for a in BURST_SIGMAS:
            same = [c for c in nights_scored if c.kind == kind and c.key == (a,)]
            recalls = [float(np.mean([x for c in same for x in found(c, c.flags[n])]))
                       for n in names if all(n in c.flags for c in same)]
            print(f"{f'{kind}, {a:g}':24}" + " ".join(f"{x:24.2f}" for x in recalls))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--spectra", type=int, default=10, help="spectra per cell")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--xrfi-python", default=os.environ.get("REACH_XRFI_PYTHON"),
                        help="an interpreter with edges-analysis (else in this process)")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    cases = [*clean_cases(rng, 4 * args.spectra), *spike_cases(rng, args.spectra),
             *hump_cases(rng, args.spectra)]
    scored, nights = night_cases(rng, args.spectra)
    start = time.perf_counter()
    for case in [*cases, *scored]:
        case.flags["ours"] = flag_sky(case.spectrum, 5.0, case.freq_mhz * 1e6)
    ours_s = time.perf_counter() - start
    for case, night in zip(scored, nights, strict=True):
        row = int(case.flags.pop("night_rows")[0])
        own = np.stack([flag_sky(x, 5.0, night.freq_mhz * 1e6) for x in night.spectrum])
        flags = flag_night(night.spectrum, own, night.freq_mhz * 1e6).flags
        case.flags["ours + night"] = flags[row]
    start = time.perf_counter()
    have_xrfi = run_xrfi([*cases, *scored], args.xrfi_python)
    xrfi_s = time.perf_counter() - start
    flaggers = list(FLAGGERS) if have_xrfi else ["ours"]
    print(f"{len(cases) + len(scored)} spectra; ours {ours_s:.1f} s, xrfi (both settings, "
          f"with its start-up) {xrfi_s:.1f} s; seed {args.seed}")
    table(cases, scored, flaggers)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
