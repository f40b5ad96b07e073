"""What a robot is: robot records and their URDF, the serial chain with controller axes and
ranges, pose conventions, and the singularity-free calibration model with its Jacobians."""
