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
``c3d``             C3D (optional ``c3d`` package)                          yes     yes
``bvh``             BVH hierarchy + motion (forward kinematics)             yes
``csv``             generic CSV (time, <joint>_x/_y/_z, <joint>_state)      yes     yes
``npz``             lossless NumPy archive                                  yes     yes
``npy``             NumPy keypoint array (T, J, D); skeleton from a sidecar yes
``openpose``        OpenPose JSON output folder (BODY_25 / COCO-18)         yes
``mediapipe``       MediaPipe Pose landmarks (JSON / CSV layout, docs)      yes
``mmpose``          MMPose predictions JSON (frames of instances)           yes     yes
``azure_kinect``    Azure Kinect Body Tracking JSON (offline_processor)     yes
``trc``             OpenSim marker trajectories                             yes     yes
``deeplabcut``      DeepLabCut .h5 / .csv (x, y, likelihood; multi-animal)  yes     yes
``lightningpose``   LightningPose predictions .csv (DeepLabCut layout)     yes     yes
``sleap_analysis``  SLEAP analysis .h5 (tracks, point scores, skeleton)     yes
``slp``             SLEAP .slp (optional ``sleap-io``)                      yes
``movement``        movement poses dataset, netCDF ``.nc``                  yes     yes
==================  =====================================================  ======  ======

Bad input raises :class:`ReadError` (a ``ValueError``) naming the file and line.
"""

from __future__ import annotations

# each format module registers itself when imported
from tobitkf.io import azure_kinect as _azure_kinect  # noqa: F401
from tobitkf.io import bvh as _bvh  # noqa: F401
from tobitkf.io import c3d as _c3d  # noqa: F401
from tobitkf.io import c3d_write as _c3d_write  # noqa: F401
from tobitkf.io import deeplabcut as _deeplabcut  # noqa: F401
from tobitkf.io import generic_csv as _csv  # noqa: F401
from tobitkf.io import keraal as _keraal  # noqa: F401
from tobitkf.io import kimore as _kimore  # noqa: F401
from tobitkf.io import krajjat as _krajjat  # noqa: F401
from tobitkf.io import lightningpose as _lightningpose  # noqa: F401
from tobitkf.io import mediapipe as _mediapipe  # noqa: F401
from tobitkf.io import mmpose as _mmpose  # noqa: F401
from tobitkf.io import movement as _movement  # noqa: F401
from tobitkf.io import npy as _npy  # noqa: F401
from tobitkf.io import npz as _npz  # noqa: F401
from tobitkf.io import ntu as _ntu  # noqa: F401
from tobitkf.io import openpose as _openpose  # noqa: F401
from tobitkf.io import qualisys as _qualisys  # noqa: F401
from tobitkf.io import sleap_analysis as _sleap_analysis  # noqa: F401
from tobitkf.io import sleap_slp as _sleap_slp  # noqa: F401
from tobitkf.io import trc as _trc  # noqa: F401
from tobitkf.io import uiprmd as _uiprmd  # noqa: F401
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.io.registry import (
    FormatSpec,
    detect_format,
    formats,
    get_format,
    input_files,
    is_companion_file,
    load,
    output_extension,
    output_files,
    read_with,
    register_format,
    save,
    unregister_format,
    writable_formats,
)

__all__ = [
    "FormatSpec",
    "OptionError",
    "ReadError",
    "detect_format",
    "formats",
    "get_format",
    "input_files",
    "is_companion_file",
    "load",
    "output_extension",
    "output_files",
    "read_with",
    "register_format",
    "save",
    "unregister_format",
    "writable_formats",
]
