"""Tracking between keyframes: proposals for the frames a worker did not key (see lk)."""
