"""The edges: measurement CSVs and instrument tables, pose lists, calib.json and camera.json,
MCAP sessions, RTDE, controller models and URDF export; atomic writes."""
