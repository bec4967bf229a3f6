"""A replaced file is the old version or the new, never half, and leaves nothing behind."""

from __future__ import annotations

import os
import stat

import h5py
import numpy as np
import pytest

from calibration.core.atomic_file import replacing, write_atomically


def test_text_is_written_with_the_umask_s_permissions_and_its_directory_made(tmp_path):
    target = tmp_path / "new" / "state.json"
    old = os.umask(0o022)
    try:
        write_atomically(target, "{}")
    finally:
        os.umask(old)
    assert target.read_text() == "{}"
    assert stat.S_IMODE(target.stat().st_mode) == 0o644
    assert [p.name for p in target.parent.iterdir()] == ["state.json"]


def test_a_file_written_in_pieces_replaces_the_old_only_when_complete(tmp_path):
    target = tmp_path / "run.h5"
    with replacing(target) as tmp, h5py.File(tmp, "w") as f:
        f["x"] = np.arange(3)

    def killed_mid_write() -> None:
        with replacing(target) as tmp:
            with h5py.File(tmp, "w") as f:
                f["x"] = np.arange(5)
            raise RuntimeError("killed mid-write")

    with pytest.raises(RuntimeError, match="killed"):
        killed_mid_write()
    with h5py.File(target, "r") as f:
        assert list(f["x"][()]) == [0, 1, 2]  # the old version, whole
    assert [p.name for p in tmp_path.iterdir()] == ["run.h5"]  # no temporary file left
