"""The report written beside a run file that holds a calibration.

After a run whose ``calibrate`` step stored a solution (``/calibration/solution``),
:class:`~reach_receiver.run.session.RunSession` (so ``reach-run`` and the daemon's jobs
alike) calls :func:`write_run_report`, which writes the engine's report
(:func:`calibration.report.writer.write_report`: a PNG per figure, ``summary.md``,
``summary.html``) into ``<run dir>/report/``. Drawing is a convenience for the people
who look: any failure is logged with its traceback and never fails the run, whose file
is already closed.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

__all__ = ["REPORT_DIRECTORY", "write_run_report"]

log = logging.getLogger(__name__)

#: The report's directory, inside the run's directory.
REPORT_DIRECTORY = "report"


def write_run_report(run_file: Path) -> Path | None:
    """Write the report of ``run_file`` beside it; its directory, or ``None`` if it failed."""
    start = time.monotonic()
    try:
        from calibration.report.writer import write_report  # matplotlib only when a report is drawn

        report = write_report(run_file, run_file.parent / REPORT_DIRECTORY)
    except Exception:  # a figure that cannot be drawn must never fail the run
        log.exception("the report of %s could not be written", run_file)
        return None
    log.info(
        "report: %d figures and %s in %.1f s",
        len(report.figures),
        report.markdown,
        time.monotonic() - start,
    )
    return report.directory
