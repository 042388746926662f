"""Rig health: per-camera faults estimated from the accepted labels, and refined calibrations."""
