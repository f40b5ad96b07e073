"""From a calibration to corrected targets, for every language alike: the IK, the pose a
target needs on the real arm, the configuration rule, failures, reports and files."""
