"""Skeleton model: topologies (joint names, bones, symmetry) and joint-track sequences."""

from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import Topology, get_topology

__all__ = ["SkeletonSequence", "Topology", "TrackingState", "get_topology"]
