"""Universal Robots URScript: pose literals of motions, set_tcp and set_payload, the joints a
motion starts from, and the lossless writer."""
