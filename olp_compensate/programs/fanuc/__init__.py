"""FANUC TP (.ls): positions with their UFRAME/UTOOL and CONFIG, the backup's frames,
registers and turn axes, and the lossless writer."""
