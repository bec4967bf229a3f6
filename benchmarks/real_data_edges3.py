"""The engine on real data: EDGES-3 lab calibration 2022-316 against EDGES' published solution.

Run ``python benchmarks/real_data_edges3.py [DATA_DIR]``; the data set defaults to
``../shared/data/edges3-2022-316`` beside the checkout (never copied into the repository).

Per load it prints the RMS over 50-190 MHz of (calibrated - physical temperature) for the
radiometric solver with evidence-chosen orders, the radiometric solver at 7 terms (the
EDGES pipeline's model size), the thesis solver and the published ``specal.txt``; the
radiometer-limited noise per channel (from the spectra's own scatter, and the floor of a
noiseless receiver), the RMS a noise-limited calibration would reach, the Cramer-Rao floor
of the calibration error, and the RMS difference between ours and the published solution.
The bounds of ``tests/test_edges3_real.py`` are shown for reference.

``python -m benchmarks.real_data_edges3 --leave-one-out`` prints only the docs'
real-data leave-one-out figures (:func:`leave_one_out_table`): the run imported as an
analyst would (``reach-cal import edges``, with the pipeline's modelled S11s, and from
the raw VNA readings of day 2022-319 with and without the receiver's path), solved and
validated by the command line's defaults.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from calibration.checks.rfi import calibrator_flags, flag_spectrum  # noqa: E402
from calibration.choice.model_fit import OrderChoice  # noqa: E402
from calibration.io import edges_text as et  # noqa: E402
from calibration.io.edges_import import load_edges3_run  # noqa: E402
from calibration.model.data import CalibrationData  # noqa: E402
from calibration.model.noise_waves import PARAMETERS, design_terms  # noqa: E402
from calibration.solve.noise_floor import noise_floor  # noqa: E402
from calibration.solve.radiometric_solver import solve_radiometric  # noqa: E402
from calibration.solve.thesis_solver import solve_thesis  # noqa: E402

DEFAULT_DATA = ROOT.parent / "shared" / "data" / "edges3-2022-316"
VNA_NAME = "edges3-2022-319-vna"  #: beside the run's directory
TEMPERATURES = "amb=306.5,hot=393.22,open=306.5,short=306.5"
_STANDARDS = ",".join(f"{s}=2022_319_14_{s[0].upper()}.s1p" for s in ("short", "open", "load"))
#: ``import edges`` options that read the raw readings of day 2022-319 (their README's kit)
VNA_OPTIONS = (
    "--device", "2022_319_14_{name}.s1p", "--standards", _STANDARDS,
    "--standards-for", "lna:" + _STANDARDS.replace("=2022_319_14_", "=2022_319_14_lna_"),
)
KIT = """{"name": "edges3", "short": {"offset": {"delay_s": 33e-12, "loss_gohm_per_s": 2.3}},
 "open": {"offset": {"delay_s": 33e-12, "loss_gohm_per_s": 2.3}},
 "load": {"resistance_ohm": 49.8, "offset": {"delay_s": 33e-12, "loss_gohm_per_s": 2.3}}}"""
S_MATCHED_K, NOISE_MARGIN = 0.05, 1.1  # as in tests/test_edges3_real.py


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def edges_cal_cross_check(data: CalibrationData, published: dict[str, np.ndarray]) -> str:
    """Largest differences to the installed edges-cal, or why it was not run."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from astropy import units
            from edges_cal import loss, noise_waves
    except ImportError as exc:
        return f"edges-cal cross-check skipped ({exc})"
    hot = data.sources["hot"]
    gain = loss.get_cable_loss_model("UT-141C-SP")(data.freq_hz / 1e6 * units.MHz, hot.gamma)
    d_gain = float(np.max(np.abs(gain - data.metadata["hot_load_gain"])))
    p = published
    d_temp = max(
        float(
            np.max(
                np.abs(
                    et.published_calibrated_temperature(p, s.p_source, s.gamma)
                    - noise_waves.calibrated_antenna_temperature(
                        s.p_source,
                        s.gamma,
                        p["s11_lna"],
                        p["sca"],
                        p["ofs"],
                        p["t_unc"],
                        p["t_cos"],
                        p["t_sin"],
                    )
                )
            )
        )
        for s in data.sources.values()
    )
    return f"edges-cal 7.1.1 cross-check: max |dG| = {d_gain:.1e}, max |dT| = {d_temp:.1e} K"


def main(directory: Path) -> None:
    t0 = time.perf_counter()
    data = load_edges3_run(directory)
    published = et.read_published_solution(directory)
    solvers = {
        "ours(ev)": lambda: solve_radiometric(data),
        "ours(7)": lambda: solve_radiometric(data, OrderChoice.fixed((7, 7, 7, 7, 7))),
        "thesis": lambda: solve_thesis(data),
    }
    solutions, timing = {}, {}
    for label, solve in solvers.items():
        t = time.perf_counter()
        solutions[label] = solve()
        timing[label] = time.perf_counter() - t
    n_rows = data.n_channels * len(data.names)

    meta = data.metadata
    print(
        f"EDGES-3 {directory.name}: {data.n_channels} channels, 50-190 MHz, "
        f"{len(data.names)} loads; loaded and solved in {time.perf_counter() - t0:.1f} s"
    )
    print(f"  averaged Dicke cycles per load (line 1 of sp*.txt): {meta['n_spectra']}")
    print(
        f"  channel spacing {meta['channel_spacing_hz'] / 1e3:.2f} kHz, noise bandwidth "
        f"{data.channel_width_hz / 1e3:.2f} kHz (Gauss smoothing of 6.10 kHz channels), "
        f"{et.INTEGRATION_PER_POSITION_S:.2f} s per position and cycle (fastspec default)"
    )
    print(
        f"  hot-load cable correction (1-G)(T_hot-T_amb): "
        f"{np.min((1 - meta['hot_load_gain']) * 86.72):.3f}-"
        f"{np.max((1 - meta['hot_load_gain']) * 86.72):.3f} K"
    )
    print("  " + edges_cal_cross_check(data, published))
    for label, sol in solutions.items():
        orders = dict(zip(PARAMETERS, sol.best_orders, strict=True))
        print(
            f"  {label:9s} orders {orders}  s^2 = {sol.posterior.noise_variance:.3f}  "
            f"({timing[label]:.2f} s)"
        )
    print()
    print(
        "Q variance: measured (channel-to-channel scatter) / radiometer equation with a "
        "noiseless receiver; implied receiver noise"
    )
    for name, src in data.sources.items():
        n = meta["n_spectra"][name]
        emp = src.q_variance_override
        assert emp is not None  # the loader always sets the measured variance
        ratio = emp / et.radiometer_q_variance(src.p_source, n)
        a = et.receiver_offset_k(src.p_source, emp, n)
        t_rx = published["sca"] * (300.0 + a) - (300.0 - published["ofs"])
        print(
            f"  {name:6s} ratio median {np.median(ratio):.2f} (range {ratio.min():.2f}-"
            f"{ratio.max():.2f}); offset a = {np.median(a):.0f} K (T* units), "
            f"T_rx = {np.median(t_rx):.0f} K (50-190 MHz: {np.percentile(t_rx, 5):.0f}-"
            f"{np.percentile(t_rx, 95):.0f} K)"
        )
    print()

    head = (
        f"{'load':6s} {'noise':>7s} {'floor0':>7s} {'expect':>7s} {'CR':>6s} | "
        f"{'ours(ev)':>8s} {'ours(7)':>8s} {'thesis':>8s} {'publish':>8s} {'bound':>7s}"
        f" | {'ev-pub':>7s} {'7-pub':>7s} {'th-pub':>7s}"
    )
    print(head)
    print("-" * len(head))
    for name, src in data.sources.items():
        assert src.q_variance_override is not None
        assert src.temperature_k is not None
        x_l = design_terms(src.gamma, data.gamma_rec).x_l
        gain_k = x_l * 1000.0 * published["sca"]
        noise = rms(gain_k * np.sqrt(src.q_variance_override))
        floor0 = rms(gain_k * np.sqrt(et.radiometer_q_variance(src.p_source, 450)))
        n_coef = sum(solutions["ours(ev)"].best_orders)
        expect = noise * np.sqrt(1 - n_coef / n_rows)
        cr = noise_floor(data, src, solutions["ours(ev)"].parameters).rms
        theirs = et.published_calibrated_temperature(published, src.p_source, src.gamma)
        ours = {
            k: s.calibrate(
                data.freq_hz, data.gamma_rec, src,
                data.channel_width_hz, data.gamma_rec_std,
            ).mean
            for k, s in solutions.items()
        }
        allowance = S_MATCHED_K * rms(x_l)
        b2 = (NOISE_MARGIN * noise) ** 2 + allowance**2
        if name == "hot":
            b2 += float(np.max((1 - meta["hot_load_gain"]) * 86.72)) ** 2
        err = {k: rms(v - src.temperature_k) for k, v in ours.items()}
        print(
            f"{name:6s} {noise:7.4f} {floor0:7.4f} {expect:7.4f} {cr:6.4f} | "
            f"{err['ours(ev)']:8.4f} {err['ours(7)']:8.4f} {err['thesis']:8.4f} "
            f"{rms(theirs - src.temperature_k):8.4f} {np.sqrt(b2):7.4f} | "
            f"{rms(ours['ours(ev)'] - theirs):7.4f} {rms(ours['ours(7)'] - theirs):7.4f} "
            f"{rms(ours['thesis'] - theirs):7.4f}"
        )
    print()
    print(
        "All in K, RMS over the 2868 channels. noise: radiometer-limited error per channel of "
        "the calibrated load\n(|X_L T_NS| sqrt(var Q), var Q from the spectra's scatter); "
        "floor0: the same for a noiseless receiver;\nexpect: RMS a noise-limited fit "
        "reaches; CR: Cramer-Rao floor of the calibration error (ours(ev) orders);\n"
        "bound: tests/test_edges3_real.py; x-pub: RMS difference of calibrated temperatures "
        "from the published solution.\nHot load at G*393.22 + (1-G)*306.5 K (published "
        "cable-loss model), the others at 306.5 K."
    )


def corrections_table(directory: Path) -> None:
    """Each load's RMS before and after the corrections that apply to this data set.

    The hot load's effective temperature through its cable's available gain (eqs.
    3.15-3.16, the UT-141C-SP cable) is the one correction of issue 14 that this data set
    needs (no MTS, no cable-fed sources, a lab). Both columns are set against the
    best-known temperatures (the hot load's with the cable's loss): the uncorrected solver
    is trained on the hot load's thermistor reading, 0.15-0.30 K warmer than what the
    receiver sees. RFI: the files hold calibrated T* spectra, so the loads' reference and
    noise-source spectra are constants and :func:`calibration.checks.rfi.calibrator_flags` finds
    nothing in them; the matched loads' own spectra are searched instead and the count is
    printed (the lab is shielded; at 5 sigma Gaussian noise alone flags almost nothing).
    """
    raw = load_edges3_run(directory, hot_load_loss=False)
    lossy = load_edges3_run(directory)
    errors: dict[str, dict[str, float]] = {}
    for label, data in (("none", raw), ("hot cable", lossy)):
        solution = solve_radiometric(data)
        errors[label] = {
            name: rms(
                solution.calibrate(data.freq_hz, data.gamma_rec, src).mean
                - np.asarray(lossy.sources[name].temperature_k)
            )
            for name, src in data.sources.items()
        }
    print("Corrections: RMS (K) of calibrated - best-known temperature, 2868 channels")
    print(f"{'load':6s} {'none':>10s} {'hot cable':>10s}")
    for name in lossy.names:
        print(f"{name:6s} {errors['none'][name]:10.4f} {errors['hot cable'][name]:10.4f}")
    flags, _ = calibrator_flags(lossy)
    own = {n: int(flag_spectrum(lossy.sources[n].p_source).sum()) for n in ("amb", "hot")}
    print(f"RFI: {int(flags.sum())} channels flagged in the reference and noise-source "
          f"spectra (constants here), {own} in the matched loads' own of {flags.size}")


def _cli(*args: str) -> tuple[int, str]:
    """``reach-cal ARGS`` in this process: exit status and what it printed."""
    import contextlib
    import io

    from calibration.cli import main as reach_cal

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = reach_cal(list(args))
    return status, out.getvalue() + err.getvalue()


def leave_one_out_table(directory: Path) -> None:
    """The docs' EDGES-3 leave-one-out figures (docs/results.md), by the command line's defaults.

    Each row: ``reach-cal import edges`` (hot-load cable UT-141C-SP, band 50-190 MHz) with
    the S11s named, then ``reach-cal solve`` (its s^2) and ``reach-cal validate
    --leave-one-out`` (open and short held out: RMS actual error, RMS predicted, their
    ratio, the 68/95 % coverage; the ambient and hot held out are refused: T_NS).
    """
    import json
    import tempfile

    from calibration.io.solution_file import read_solution
    from calibration.solve.solution import Solution

    variants: list[tuple[str, tuple[str, ...]]] = [("modelled S11s (s11_modelled.txt)", ())]
    vna = directory.parent / VNA_NAME
    if vna.is_dir():
        options = ("--vna", str(vna), *VNA_OPTIONS)
        variants += [
            ("raw VNA, receiver path (--receiver-cable edges3)",
             (*options, "--receiver-cable", "edges3")),
            ("raw VNA, no receiver path (--receiver-path none)",
             (*options, "--receiver-path", "none")),
        ]  # fmt: skip
    else:
        print(f"({vna} is absent: the raw VNA rows are left out)")
    print(f"EDGES-3 leave-one-out by the command line ({directory.name}; reach-cal import "
          "edges --hot-cable ut141c, solve, validate --leave-one-out), K:")
    head = f"{'S11s':52s} {'s^2':>7s} {'held out':8s} {'actual':>8s} {'pred':>8s} {'ratio':>6s} "
    print(head + f"{'in68':>5s} {'in95':>5s}  orders")
    with tempfile.TemporaryDirectory() as tmp:
        kit = Path(tmp) / "kit.json"
        kit.write_text(KIT)
        for label, extra in variants:
            run, sol, report = (Path(tmp) / n for n in ("run.h5", "sol.h5", "loo.json"))
            for path in (run, sol, report):
                path.unlink(missing_ok=True)
            kit_args = ("--kit", str(kit)) if extra else ()
            steps = (
                ("import", "edges", str(directory), "-o", str(run), "--temperatures",
                 TEMPERATURES, "--hot-cable", "ut141c", *extra, *kit_args),
                ("solve", str(run), "-o", str(sol)),
                ("validate", str(run), "--leave-one-out", "-o", str(report)),
            )  # fmt: skip
            for step in steps:
                status, text = _cli(*step)
                if status:
                    raise SystemExit(f"reach-cal {' '.join(step)} failed ({status}):\n{text}")
            solved = read_solution(sol)
            assert isinstance(solved, Solution), "the default solver is polynomial"
            s2 = solved.posterior.noise_variance
            for row in json.loads(report.read_text())["held_out"]:
                if row["refused"]:
                    continue
                print(
                    f"{label:52s} {s2:7.3f} {row['name']:8s} {row['rms_error_k']:8.3f} "
                    f"{row['rms_predicted_k']:8.3f} {row['ratio']:6.2f} {row['inside_68']:5.2f} "
                    f"{row['inside_95']:5.2f}  {','.join(map(str, row['orders']))}"
                )


if __name__ == "__main__":
    flags = [a for a in sys.argv[1:] if a.startswith("--")]
    paths = [a for a in sys.argv[1:] if not a.startswith("--")]
    where = Path(paths[0]) if paths else DEFAULT_DATA
    if "--leave-one-out" not in flags:
        main(where)
        print()
        corrections_table(where)
        print()
    leave_one_out_table(where)
