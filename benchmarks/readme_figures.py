"""The two figures README.md shows, drawn from a simulated REACH run.

Run ``python -m benchmarks.readme_figures`` (a few seconds). It simulates a run of the
twelve REACH calibrators and the mock antenna (seed 1, 50-130 MHz, 600 s per Dicke
position, channels of 8 iTPM channels, ~98 kHz, so that a panel's channels can be told
apart), solves it with the default solver and writes, with :mod:`calibration.report.figures`:

* ``docs/figures/parameters.png``: the noise-wave parameters with their 68/95 % bands
  and the simulated truth;
* ``docs/figures/sources.png``: every source calibrated, its residual against its
  known temperature and its predicted radiometer and calibration noise.

The PNGs are reduced to 256 colours (Pillow, which matplotlib installs) to stay under
200 kB each, the README's limit.
"""

from __future__ import annotations

import argparse
import io
from pathlib import Path

from matplotlib.figure import Figure
from PIL import Image

from calibration.model.simulate import ITPM_CHANNEL_WIDTH_HZ, SimulationConfig, simulate_run
from calibration.report import figures
from calibration.report.figures.style import DPI
from calibration.solve.radiometric_solver import solve_radiometric

OUT = Path(__file__).resolve().parent.parent / "docs" / "figures"
LIMIT_BYTES = 200_000


def save_small(fig: Figure, path: Path) -> int:
    """Write ``fig`` as a 256-colour PNG; returns its size in bytes."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    buffer.seek(0)
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(256).save(path, optimize=True)
    return path.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("-o", "--out", type=Path, default=OUT, help="directory to write")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    run = simulate_run(SimulationConfig(channel_width_hz=8 * ITPM_CHANNEL_WIDTH_HZ), rng=1)
    data = run.data
    solution = solve_radiometric(data)
    sources = {**data.sources, "ant": run.validation}
    spectra = {
        name: solution.calibrate(
            data.freq_hz, data.gamma_rec, src,
            data.channel_width_hz, data.gamma_rec_std,
        )
        for name, src in sources.items()
    }
    references = {
        name: src.temperature_k
        for name, src in data.sources.items()
        if src.temperature_k is not None
    }
    references["ant"] = run.validation_temperature_k
    drawn = {
        "parameters.png": figures.noise_wave_parameters(solution, truth=run.truth.parameters),
        "sources.png": figures.calibrated_sources(spectra, references),
    }
    for name, fig in drawn.items():
        size = save_small(fig, args.out / name)
        print(f"wrote {args.out / name} ({size / 1e3:.0f} kB)")
        if size > LIMIT_BYTES:
            raise SystemExit(f"{name} is {size} bytes, over the README's {LIMIT_BYTES}")


if __name__ == "__main__":
    main()
