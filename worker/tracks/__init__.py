"""Annotation tracks: the keyframe model, interpolation, provenance and checks.

A track is one point of a task (a hand joint or an object landmark) through a clip of F frames,
stored as keyframes sorted by frame with positions in image pixels (x right, y down, 0 <= x <
width, 0 <= y < height). An occluded keyframe may carry a guessed position or none.

- :mod:`worker.tracks.keyframes`: one keyframe, its stored and accepted forms, its source;
- :mod:`worker.tracks.interpolate`: a track's value at every frame (the twin of the page's
  interpolate.js);
- :mod:`worker.tracks.sources`: where each frame's value came from, and which frames the
  worker decided;
- :mod:`worker.tracks.validate`: whether saved keyframes are well formed and in the image;
- :mod:`worker.tracks.readiness`: whether a task's tracks are ready to submit, and signs of
  careless work;
- :mod:`worker.tracks.spans`: frame spans, as the messages name them.
"""
