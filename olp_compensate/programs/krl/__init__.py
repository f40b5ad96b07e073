"""KUKA KRL: a .src with its .dat (and the controller's $config.dat), read as six-number
targets with their BASE/TOOL frames, status and turn, and written back losslessly."""
