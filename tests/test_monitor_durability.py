"""The metrics database survives ``kill -9``: every batch reported committed is there.

A real subprocess writes batches of readings through :class:`MetricsDatabase` (WAL,
``synchronous=FULL``), printing each batch's number once its transaction committed;
the test kills it with SIGKILL mid-stream, then opens the file: it must pass SQLite's
integrity check and hold every reported batch whole (no half batch).
"""

import signal
import sqlite3
import subprocess
import sys

from reach_receiver.monitor.database import MetricsDatabase

SERIES = 50
WRITER = """
import sys
from pathlib import Path
from reach_receiver.monitor.database import MetricsDatabase
from reach_receiver.monitor.readings import Reading
db = MetricsDatabase(Path(sys.argv[1]))
for n in range(10**9):
    db.write([Reading("reach_test_value", float(n), "1", 1.7e9 + 60 * n,
                      labels={"i": str(i)}) for i in range(int(sys.argv[2]))])
    print(n, flush=True)
"""


def test_a_writer_killed_with_sigkill_leaves_every_committed_batch(tmp_path):
    path = tmp_path / "metrics.sqlite"
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(SERIES)],
                              stdout=subprocess.PIPE, text=True)
    last = -1
    for line in writer.stdout:
        last = int(line)
        if last >= 200:
            break
    writer.send_signal(signal.SIGKILL)
    writer.wait(timeout=10)
    writer.stdout.close()
    assert writer.returncode == -signal.SIGKILL
    with sqlite3.connect(path) as raw:
        assert raw.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    database = MetricsDatabase(path)
    rows = database.count()
    assert rows >= (last + 1) * SERIES
    assert rows % SERIES == 0  # whole batches only
    values = [p.value for p in database.series("reach_test_value{i=7}", 0.0)]
    assert values[: last + 1] == [float(n) for n in range(last + 1)]
    database.close()
