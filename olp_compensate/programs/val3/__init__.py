"""Stäubli VAL3: a project's data file (.dtx) and its programs (.pgx): points and frames,
configuration words, and the lossless writer."""
