"""Solve: per-sequence runs that fit MANO hand and 6D object poses to the accepted labels."""
