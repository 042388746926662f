"""Assistance for the annotation page, and the checks that keep it honest.

- :mod:`worker.assist.lk`: point tracking, Lucas-Kanade proposals between a worker's keyframes;
- :mod:`worker.assist.stretches`: interpolated stretches of a track checked against its own
  view's images with the same tracker;
- :mod:`worker.assist.prefill`: pre-fill suggestions for one view from the accepted work of the
  others (triangulated, projected, visibility from depth);
- :mod:`worker.assist.prelabel`: hand proposals from a keypoint model (MediaPipe, the optional
  extra ``prelabel``) for a view nobody has labelled yet, and their score against the truth;
- :mod:`worker.assist.checks`: check suggestions, the few cells per assignment shown off the
  point so that QC can tell a worker who looks from one who accepts everything.

Pure: arrays in, arrays out.
"""
