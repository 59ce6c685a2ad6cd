"""movement's poses datasets and their netCDF files (``.nc``).

A movement poses dataset (an :class:`xarray.Dataset`, ``ds_type = "poses"``) holds

* ``position`` with dims ``(time, space, keypoints, individuals)``, ``space`` = ``x``,
  ``y`` (and ``z``);
* ``confidence`` with dims ``(time, keypoints, individuals)`` (NaN where none);
* attributes ``fps``, ``time_unit`` (``"seconds"``: ``time`` is in seconds;
  ``"frames"``: frame numbers), ``source_software``, ``source_file``.

:func:`from_movement` gives one :class:`SkeletonSequence` per individual (``body_id`` =
its name; positions in pixels for 2-D, unknown units for 3-D unless the dataset says
``units``); :func:`to_movement` builds such a dataset (loadable by movement, e.g.
``movement.io.save_poses.to_dlc_file``) and records the units, the bones and the
left/right pairs in the attributes ``tobitkf_units``, ``tobitkf_parents`` and
``tobitkf_symmetry``, a smoothed sequence's posterior standard deviation and sample
states in the variables ``tobitkf_std`` and ``tobitkf_sample_state`` (dims ``(time,
keypoints, individuals)``; movement's own functions pass them by), and its provenance
(``metadata["provenance"]``) as JSON text in the attribute ``tobitkf_provenance`` (the
provenance the individuals share, else a list with each one's), so that a round trip
loses nothing.
The ``.nc`` files are that dataset written by ``Dataset.to_netcdf`` (movement saves and
loads its datasets this way); :func:`read_movement` / :func:`write_movement` read and
write them (xarray and h5netcdf: ``pip install 'tobitkf[pose]'``).
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.core.version import __version__
from tobitkf.io._json import attach_provenance, provenance_text
from tobitkf.io._pose import (
    check_hdf5_opens,
    frame_numbers,
    hdf5_reason,
    is_hdf5,
    pose_arrays,
    require,
    sequences_from_arrays,
    sniff_hdf5,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import KNOWN_UNITS, SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["from_movement", "read_movement", "sniff_movement", "to_movement", "write_movement"]

_NETCDF3_MAGIC = "CDF\x01", "CDF\x02", "CDF\x05"


def from_movement(
    ds: Any, *, path: Any = "<movement dataset>", implausible: str = "error"
) -> list[SkeletonSequence]:
    """Sequences (one per individual) of a movement poses dataset (module docstring).
    ``implausible`` (``"error"`` or ``"missing"``): what to do with a coordinate beyond
    the plausibility bound (or infinite)."""
    xr = require("xarray", "movement datasets")
    if not isinstance(ds, xr.Dataset):
        raise TypeError(f"expected an xarray Dataset (movement poses), got {type(ds).__name__}")
    if "position" not in ds:
        raise ValueError("expected a movement poses dataset with a 'position' variable")
    pos_da = ds["position"]
    need = {"time", "space", "keypoints", "individuals"}
    if set(pos_da.dims) != need:
        raise ValueError(f"position must have dims {sorted(need)}, found {list(pos_da.dims)}")
    space = [str(s) for s in pos_da["space"].values]
    if space not in (["x", "y"], ["x", "y", "z"]):
        raise ValueError(f"expected space coordinates x, y[, z], found {space}")
    pos = pos_da.transpose("time", "individuals", "keypoints", "space").values
    conf = None
    if "confidence" in ds:
        conf = ds["confidence"].transpose("time", "individuals", "keypoints").values
        if np.isnan(conf).all():
            conf = None
    attrs = dict(ds.attrs)
    time = np.asarray(ds["time"].values, dtype=float)
    fps = attrs.get("fps")
    fps = None if fps is None or (isinstance(fps, float) and np.isnan(fps)) else float(fps)
    timestamps = None
    if attrs.get("time_unit", "seconds") == "seconds" and time.size:
        if fps is None or not np.array_equal(time, np.arange(time.size) / fps):
            timestamps = time
    elif time.size and not np.array_equal(time, np.arange(time.size)):
        attrs["frames"] = time.astype(np.int64)
    units = attrs.get("tobitkf_units", "px" if len(space) == 2 else None)
    if isinstance(units, str) and units not in KNOWN_UNITS:
        units = None
    keypoints = [str(k) for k in ds["keypoints"].values]
    individuals = [_text(i) for i in ds["individuals"].values]
    meta: dict[str, Any] = {"source_software": attrs.get("source_software")}
    if "frames" in attrs:
        meta["frames"] = attrs["frames"]
    if attrs.get("source_file"):
        meta["source_file"] = str(attrs["source_file"])
    seqs = sequences_from_arrays(
        path, pos, conf, keypoints, individuals, fmt="movement", units=units, fps=fps,
        timestamps=timestamps, metadata=meta, implausible=implausible,
    )  # fmt: skip
    parents = attrs.get("tobitkf_parents")
    if parents is not None and len(np.atleast_1d(parents)) == len(keypoints):
        try:
            topo = Topology.from_names(
                keypoints, [int(p) for p in np.atleast_1d(parents)], name="movement"
            )
            symmetry = np.asarray(attrs.get("tobitkf_symmetry", []), dtype=np.int64).reshape(-1, 2)
            if symmetry.size and symmetry.min() >= 0 and symmetry.max() < len(keypoints):
                topo = Topology(topo.name, topo.joints, topo.parents, tuple(map(tuple, symmetry)),
                                topo.up_axis)  # fmt: skip
            seqs = [s.replace(topology=topo) for s in seqs]
        except ValueError:
            pass  # not a tree: keep the keypoints without bones
    attach_provenance(
        path, seqs, attrs.get("tobitkf_provenance"), "the attribute tobitkf_provenance"
    )
    return _smoothed_fields(ds, seqs)


def _smoothed_fields(ds: Any, seqs: list[SkeletonSequence]) -> list[SkeletonSequence]:
    """``seqs`` with the ``std`` and ``sample_state`` that :func:`to_movement` wrote."""
    from tobitkf.skeleton.sequence import SampleState

    fields: dict[str, np.ndarray] = {}
    for name, var in (("std", "tobitkf_std"), ("sample_state", "tobitkf_sample_state")):
        if var not in ds:
            continue
        da = ds[var]
        if set(da.dims) != {"time", "keypoints", "individuals"}:
            raise ValueError(f"{var} must have dims time, keypoints, individuals")
        values = da.transpose("time", "individuals", "keypoints").values
        if name == "sample_state" and not np.isin(values, [int(v) for v in SampleState]).all():
            raise ValueError(f"{var} holds a value that is no sample state")
        fields[name] = values
    if not fields:
        return seqs
    return [s.replace(**{k: v[:, i] for k, v in fields.items()}) for i, s in enumerate(seqs)]


def _text(v: Any) -> Any:
    if isinstance(v, bytes):
        return v.decode("utf-8", errors="replace")
    return v.item() if isinstance(v, np.generic) else v


def to_movement(sequences: SkeletonSequence | Sequence[SkeletonSequence]) -> Any:
    """A movement poses dataset of one sequence or several (one per individual)."""
    xr = require("xarray", "movement datasets")
    seqs = [sequences] if isinstance(sequences, SkeletonSequence) else list(sequences)
    arr = pose_arrays(seqs)
    first = seqs[0]
    if first.timestamps is not None:
        time, unit = first.timestamps, "seconds"
    elif first.fps is not None:
        time, unit = np.arange(first.n_frames) / first.fps, "seconds"
    else:
        frames = frame_numbers(first)  # the input's frame numbers, else 0, 1, ...
        time = np.arange(first.n_frames) if frames is None else frames
        time, unit = np.asarray(time, dtype=float), "frames"
    attrs: dict[str, Any] = {
        "source_software": f"tobitkf {__version__}",
        "ds_type": "poses",
        "time_unit": unit,
        "tobitkf_parents": np.asarray(first.topology.parents, dtype=np.int64),
    }
    if first.topology.symmetry:
        attrs["tobitkf_symmetry"] = np.asarray(first.topology.symmetry, dtype=np.int64).ravel()
    if first.fps is not None:
        attrs["fps"] = float(first.fps)
    if first.units is not None:
        attrs["tobitkf_units"] = first.units
    src = first.metadata.get("source")
    if src:
        attrs["source_file"] = str(src)
    provenance = provenance_text(seqs)
    if provenance is not None:
        attrs["tobitkf_provenance"] = provenance
    per_sample = ("time", "keypoints", "individuals")
    variables: dict[str, Any] = {
        "position": (
            ("time", "space", "keypoints", "individuals"),
            arr.positions.transpose(0, 3, 2, 1),
        ),
        "confidence": (per_sample, arr.confidence.transpose(0, 2, 1)),
    }
    if all(s.std is not None for s in seqs):  # a smoothed output: what it said of each sample
        variables["tobitkf_std"] = (per_sample, np.stack([s.std for s in seqs], axis=2))
    if all(s.sample_state is not None for s in seqs):
        states = np.stack([s.sample_state for s in seqs], axis=2).astype(np.int8)
        variables["tobitkf_sample_state"] = (per_sample, states)
    return xr.Dataset(
        variables,
        coords={
            "time": np.asarray(time, dtype=float),
            "space": ["x", "y", "z"][: arr.n_dims],
            "keypoints": arr.keypoints,
            "individuals": arr.individuals,
        },
        attrs=attrs,
    )


def read_movement(
    path: str | os.PathLike[str], implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a movement poses dataset saved as netCDF (``Dataset.to_netcdf``);
    ``implausible`` as for :func:`from_movement`."""
    p = Path(path)
    xr = require("xarray", "reading movement netCDF files")
    engine = _engine_for(p)
    if engine is None and is_hdf5(p) and importlib.util.find_spec("netCDF4") is None:
        # a netCDF-4 file and no library for it: xarray would call it no netCDF at all
        require("h5netcdf", "reading movement netCDF-4 files")
    if engine == "h5netcdf" and is_hdf5(p):  # h5py reads it anyway: no library clash
        check_hdf5_opens(p, "reading movement netCDF files")
    try:
        with xr.open_dataset(p, engine=engine) as ds:
            ds.load()
            kind = ds.attrs.get("ds_type", "poses")
            if kind != "poses":
                raise ReadError(p, None, f"a movement {kind!r} dataset, not poses")
            return from_movement(ds, path=p, implausible=implausible)
    except ReadError:
        raise
    except ImportError:
        raise
    except (OSError, ValueError, TypeError, KeyError) as exc:
        reason = hdf5_reason(exc)
        raise ReadError(p, None, f"not a movement poses netCDF file ({reason})") from None


def _h5netcdf() -> str | None:
    try:
        import h5netcdf  # noqa: F401
    except ImportError:
        return None
    return "h5netcdf"


def _engine_for(path: Path) -> str | None:
    """h5netcdf for netCDF-4 (HDF5) files when installed: the netCDF4 package bundles its
    own HDF5 library, which clashes with h5py's in the same process (a RuntimeError once
    h5py has been used, e.g. by a DeepLabCut or SLEAP reader); scipy for classic files."""
    try:
        with open(path, "rb") as f:
            head = f.read(8)
    except OSError:
        return None
    if head.decode("latin-1").startswith(_NETCDF3_MAGIC):
        return "scipy"
    return _h5netcdf()


def write_movement(sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str]) -> None:
    """Write sequences as a movement poses dataset in a netCDF file."""
    ds = to_movement(list(sequences))
    ds.to_netcdf(Path(path), engine=_h5netcdf())


def sniff_movement(path: Path, head: str) -> int:
    """Score: a netCDF file (HDF5 or classic) holding a ``position`` variable."""
    if head.startswith(_NETCDF3_MAGIC):
        return 80 if b"position" in head.encode("utf-8", "replace") else 10
    return sniff_hdf5(
        path, 90, lambda f: "position" in f and "keypoints" in f,
        without_h5py=4 if path.suffix.lower() == ".nc" else 0,
    )  # fmt: skip


register_format(
    "movement", read_movement, write_movement, (".nc",), sniff_movement,
    description="movement poses dataset (netCDF)", aliases=("netcdf",),
)  # fmt: skip
