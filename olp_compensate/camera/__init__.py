"""The seed's camera measurement system (Motta 2006, sections 8-9): one camera on the
robot's flange looking at a printed board of dots.

- :mod:`.model` the RAC camera model (pixels from camera-frame points);
- :mod:`.board` the board (dots in the board frame, board.json);
- :mod:`.detect` subpixel dot centres ordered by the marker dot;
- :mod:`.detect_opencv`, :mod:`.find_board` the boards users own (OpenCV's circle grids,
  ChArUco boards, chessboards), a ChArUco board's partial views included;
- :mod:`.rac`, :mod:`.refine`, :mod:`.calibrate` Tsai's RAC with the seed's changes, then a
  full Levenberg-Marquardt refinement; :mod:`.rac_batch` the RAC's stages for all views at
  once (its searches), :mod:`.block_lm` the refinement's solver on per-view blocks (Schur
  complement on the poses);
- :mod:`.measure` the camera's pose in the board frame per view;
- :mod:`.render` what a camera sees of the board (virtual campaigns, tests, benchmarks);
- :mod:`.drawing` the board for printing and detection pictures.
"""
