"""Readers and writers of skeleton / motion-capture files, with format auto-detection.

``load(path, format="auto")`` returns a list of :class:`~tobitkf.SkeletonSequence` (one
per body); ``save(sequences, path, format=...)`` writes them. Registered formats:

==================  =====================================================  ======  ======
name                content                                                read    write
==================  =====================================================  ======  ======
``ntu``             NTU RGB+D ``.skeleton`` (multi-body Kinect V2)          yes     yes
``kimore``          KIMORE JointPosition CSV (25 × x, y, z, state)          yes
``keraal_kinect``   KERAAL Kinect text (25 × position + quaternion wxyz)    yes
``keraal_vicon``    KERAAL Vicon text (17 targets, mm)                      yes
``uiprmd_kinect``   UI-PRMD Kinect positions + angles (22-joint hierarchy)  yes
``uiprmd_vicon``    UI-PRMD Vicon (39 Plug-in Gait markers, mm)             yes
``krajjat``         Kinect TSV with timestamps (krajjat)                    yes
``qualisys``        Qualisys QTM TSV (mm)                                   yes
``c3d``             C3D (optional ``c3d`` package)                          yes
``bvh``             BVH hierarchy + motion (forward kinematics)             yes
``csv``             generic CSV (time, <joint>_x/_y/_z, <joint>_state)      yes     yes
``npz``             lossless NumPy archive                                  yes     yes
==================  =====================================================  ======  ======

Bad input raises :class:`ReadError` (a ``ValueError``) naming the file and line.
"""

from __future__ import annotations

from tobitkf.io import bvh as _bvh
from tobitkf.io import c3d as _c3d
from tobitkf.io import generic_csv as _csv
from tobitkf.io import keraal as _keraal
from tobitkf.io import kimore as _kimore
from tobitkf.io import krajjat as _krajjat
from tobitkf.io import npz as _npz
from tobitkf.io import ntu as _ntu
from tobitkf.io import qualisys as _qualisys
from tobitkf.io import uiprmd as _uiprmd
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.io.registry import (
    FormatSpec,
    detect_format,
    formats,
    get_format,
    is_companion_file,
    load,
    register_format,
    save,
    unregister_format,
)

__all__ = [
    "FormatSpec",
    "OptionError",
    "ReadError",
    "detect_format",
    "formats",
    "get_format",
    "is_companion_file",
    "load",
    "register_format",
    "save",
    "unregister_format",
]

register_format(
    "ntu", _ntu.read_ntu, _ntu.write_ntu, (".skeleton",), _ntu.sniff_ntu,
    description="NTU RGB+D .skeleton (Kinect V2, multi-body)",
)  # fmt: skip
register_format(
    "kimore", _kimore.read_kimore, None, (".csv",), _kimore.sniff_kimore,
    description="KIMORE JointPosition CSV with tracking states",
)  # fmt: skip
register_format(
    "keraal_kinect", _keraal.read_keraal_kinect, None, (".txt",), _keraal.sniff_keraal_kinect,
    description="KERAAL Kinect V2 text (positions + quaternions w,x,y,z)",
)  # fmt: skip
register_format(
    "keraal_vicon", _keraal.read_keraal_vicon, None, (".txt",), _keraal.sniff_keraal_vicon,
    description="KERAAL Vicon text (17 ART targets, mm)",
)  # fmt: skip
register_format(
    "uiprmd_kinect", _uiprmd.read_uiprmd_kinect, None, (".txt.gz",),
    _uiprmd.sniff_uiprmd_kinect, description="UI-PRMD Kinect positions + angles",
)  # fmt: skip
register_format(
    "uiprmd_vicon", _uiprmd.read_uiprmd_vicon, None, (".txt.gz",), _uiprmd.sniff_uiprmd_vicon,
    description="UI-PRMD Vicon (39 Plug-in Gait markers, mm)",
)  # fmt: skip
register_format(
    "krajjat", _krajjat.read_krajjat, None, (".tsv",), _krajjat.sniff_krajjat,
    description="Kinect TSV with timestamps (krajjat)", aliases=("kinect_tsv",),
)  # fmt: skip
register_format(
    "qualisys", _qualisys.read_qualisys, None, (".tsv",), _qualisys.sniff_qualisys,
    description="Qualisys Track Manager TSV (mm)", aliases=("qtm",),
)  # fmt: skip
register_format(
    "c3d", _c3d.read_c3d, None, (".c3d",), _c3d.sniff_c3d,
    description="C3D (needs the optional 'c3d' package)",
)  # fmt: skip
register_format(
    "bvh", _bvh.read_bvh, None, (".bvh",), _bvh.sniff_bvh,
    description="BVH hierarchy + motion",
)  # fmt: skip
register_format(
    "csv", _csv.read_csv, _csv.write_csv, (".csv",), _csv.sniff_csv,
    description="generic skeleton CSV", aliases=("generic_csv",),
)  # fmt: skip
register_format(
    "npz", _npz.read_npz, _npz.write_npz, (".npz",), _npz.sniff_npz,
    description="lossless NumPy archive",
)  # fmt: skip
