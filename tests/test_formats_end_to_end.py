"""Every real file format: read, smooth with every method, write, read back (issue 4)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import data_file
from tobitkf.io import load, save
from tobitkf.smoothing.api import method_names, smooth

#: one real recording per format in ../shared/data
FILES = {
    "kimore": "kimore/JointPositionExercise1.csv",
    "keraal_kinect": "keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt",
    "keraal_vicon": "keraal/G3-Vicon-CTK-P1T1-Unknown-C-0.txt",
    "uiprmd_kinect": "ui-prmd/Segmented Movements/Kinect/Positions/m01_s01_e01_positions.txt.gz",
    "uiprmd_vicon": "ui-prmd/Segmented Movements/Vicon/Positions/m01_s01_e01_positions.txt.gz",
    "krajjat": "krajjat/sequence_ainhoa_trimmed.tsv",
    "qualisys": "krajjat/test_sequence_qtm_2.tsv",
    "c3d": "btkdata/PiG_Motion-FlatFoot-Full.c3d",
    "bvh": "cmu-mocap/scaled_131_01.bvh",
}


@pytest.fixture(scope="module")
def recordings():
    return {fmt: load(data_file(rel))[0] for fmt, rel in FILES.items()}


@pytest.mark.parametrize("fmt", sorted(FILES))
def test_every_method_smooths_and_round_trips(fmt, recordings, tmp_path):
    raw = recordings[fmt]
    for method in method_names():
        out = smooth(raw, method=method)
        assert out.positions.shape == raw.positions.shape, method
        # an estimate wherever the input had a value (nothing is lost)
        lost = np.isnan(out.positions) & np.isfinite(raw.positions)
        assert not lost.any(), f"{method}: {lost.sum()} samples lost"
        assert out.joint_names == raw.joint_names and out.fps == raw.fps
    # write and read back the last output in both lossless-for-positions formats
    for ext, format_name in ((".csv", "csv"), (".npz", "npz")):
        path = tmp_path / f"out{ext}"
        save([out], path, format=format_name)
        (back,) = load(path)
        assert back.joint_names == out.joint_names
        np.testing.assert_array_equal(np.isnan(back.positions), np.isnan(out.positions))
        np.testing.assert_allclose(
            back.positions, out.positions, rtol=0, atol=1e-12, equal_nan=True
        )
